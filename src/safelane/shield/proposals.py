"""Nominal proposals are checked, not trusted.

A planner's answer must be two arrays of numbers of the batch's shape ``(B,)``; anything else (a wrong shape, a
string, booleans, ``None``) is a programming error and raises a ``TypeError``/``ValueError`` naming the planner.
A finite action inside the mechanical limits (to ``1e-9`` m/s²) is a valid proposal; a non-finite one or one
outside the limits is a *failed proposal*: it never reaches the state — the supervisor treats the row as if the
planner had proposed to hesitate (``a_x = 0`` and the lateral speed driven to zero, still checked) and aborts if
that is unsafe — and it is counted per scenario (``n_invalid_proposals`` in the results table).
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, jitable
from ..tolerances import ACCEL_TOL_MPS2

_RANGE_TOL = ACCEL_TOL_MPS2


def check_proposal(planner, proposal, batch: int, prm: Params):
    """``(a_x, a_y, invalid)`` from a planner's raw answer; invalid rows hold ``0`` (see the module docstring)."""
    out = proposal_arrays(planner, proposal, batch)
    with np.errstate(invalid="ignore"):
        ok, a_x, a_y = proposal_core(ARRAY, *out, prm)
    return a_x, a_y, ~ok


def proposal_arrays(planner, proposal, batch: int) -> list[np.ndarray]:
    """``[a_x, a_y]`` as float arrays of shape ``(batch,)``, or the ``TypeError``/``ValueError`` naming the planner and
    what is wrong (the module docstring); their values are :func:`proposal_core`'s to judge."""
    name = planner if isinstance(planner, str) else getattr(planner, "__name__", type(planner).__name__)
    who = name if name.startswith("the ") else f"nominal planner {name}"  # not "nominal planner the nominal planner"
    if not isinstance(proposal, tuple | list) or len(proposal) != 2:
        raise TypeError(f"{who} must return a pair (a_x, a_y); got {type(proposal).__name__}")
    out = []
    for axis, value in zip(("a_x", "a_y"), proposal, strict=True):
        arr = np.asarray(value)
        if arr.dtype.kind not in "fiu":
            raise TypeError(
                f"{who} returned {axis} of dtype {arr.dtype} ({type(value).__name__}); numbers are required"
            )
        if arr.shape != (batch,):
            raise ValueError(f"{who} returned {axis} of shape {arr.shape}; expected ({batch},)")
        out.append(arr.astype(float))
    return out


def proposal_core(xp, a_x, a_y, lim):
    """``(ok, a_x, a_y)``: whether the proposal is valid — finite and inside the mechanical limits (``lim``:
    ``Params`` or its ``Limits``) to ``1e-9`` m/s² — and the proposal with ``0`` where it is not. Backend-generic:
    :func:`check_proposal` evaluates it on arrays, the compiled closed loop per row. A NaN or an infinity fails the
    range comparisons themselves (the limits are finite)."""
    ok = (a_x >= -lim.a_x_d - _RANGE_TOL) & (a_x <= lim.a_x_a + _RANGE_TOL) & (abs(a_y) <= lim.a_y_m + _RANGE_TOL)
    return ok, xp.where(ok, a_x, 0.0), xp.where(ok, a_y, 0.0)


jitable(proposal_core)
