"""The compiled evasion check (numba): :func:`~.evasion.evasion_parts` itself, compiled, one row at a time.

No formula lives here. :func:`exists_kernel` and :func:`plan_kernel` are loops over the rows of a batch that call
the backend-generic closed form :func:`~.evasion.evasion_parts` (Eq. 5 ``lateral_core``, Eqs. 6–8
``longitudinal_core``, Eq. 9) on ``SCALAR``, the Python-float backend, which :mod:`._compile` teaches numba; the row
function :func:`_plan_parts` is ``plan_kernel``'s row. The uncompiled path evaluates the same functions on NumPy
arrays.

**Same bits.** numba compiles without ``fastmath`` (LLVM neither contracts ``a * b + c`` into a fused multiply-add
nor reassociates), ``sqrt`` and ``/`` are correctly rounded in both, ``SCALAR``'s ``maximum``/``minimum`` propagate
NaN as NumPy's do, and a row evaluates every candidate the NumPy path evaluates, in the same order. The verdicts
and every part of the plan are bit-identical to the NumPy path's (``tests/test_fast_core.py``,
``tests/test_fast_plan.py``).

Imported only where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1`` (:func:`~.evasion.fast_kernel`). Compiled
code is cached on disk (``cache=True``); :mod:`._fast_base` drops the cache when any source it compiles changed.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types

from . import _compile
from ._backend import SCALAR, Limits
from ._fast_base import _B, _F, announce_compiles, kernel

# responsible.responsible_bound's dispatch finds its kernel here (fast_kernel() is this module): re-exported
from ._fast_responsible import responsible, responsible_kernel  # noqa: F401
from .evasion import PARTS, evasion_parts

_compile.register_rows()
announce_compiles()

#: The float fields of the plan, in the rows of :func:`plan_kernel`'s ``floats`` output.
FLOAT_PARTS = PARTS[:10]
#: ``exists`` and the bool fields of the plan, in the rows of :func:`plan_kernel`'s ``flags`` output.
BOOL_PARTS = ("exists", *PARTS[10:])

_OUT = (types.Array(types.float64, 2, "C"), types.Array(types.bool_, 2, "C"))
# One explicit signature each (compiled at import, or loaded from the cache): read-only 1-D arrays of any layout, so
# contiguous inputs, broadcast scalars (stride 0) and read-only views all take the same machine code.
_EXISTS_SIGNATURE = types.void(*(_F,) * 9, _B, _F, _F, *(types.float64,) * 5, types.Array(types.bool_, 1, "C"), _OUT[0])
_PLAN_SIGNATURE = types.void(*(_F,) * 9, _B, _F, _F, *(types.float64,) * 5, *_OUT)


@numba.njit(error_model="numpy", nogil=True)
def _plan_parts(py, vy, p, v, p1, v1, a1, fp, fv, aggr, margin, fmargin, a_a, a_d, a_y, y_safe, tol):
    """One row of :func:`~.evasion.evasion_parts`: ``(floats, flags)`` as tuples in the orders of
    :data:`FLOAT_PARTS` and :data:`BOOL_PARTS`."""
    r = evasion_parts(SCALAR, p, py, v, vy, p1, v1, a1, fp, fv, aggr, margin, fmargin, Limits(a_a, a_d, a_y, y_safe),
                      tol)  # fmt: skip
    return (r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10]), (r[0], r[11], r[12], r[13], r[14])


@kernel(_EXISTS_SIGNATURE)
def exists_kernel(
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, lead_margin, follow_margin, a_a, a_d,
    a_y, y_safe, tol, out, gaps,
):  # fmt: skip
    """Write :func:`~.evasion.evasion_parts`' ``exists`` for each row into ``out`` (bool, length ``n``).

    Every input is a 1-D array of length ``n`` (stride 0 for a broadcast scalar). ``gaps`` is ``(2, n)`` to also
    receive ``lead_gap`` and ``follow_gap``, or ``(2, 0)``."""
    n = out.shape[0]
    want_gaps = gaps.shape[1] == n and n > 0
    prm = Limits(a_a, a_d, a_y, y_safe)
    for i in range(n):
        r = evasion_parts(
            SCALAR, ego_px[i], ego_py[i], ego_vx[i], ego_vy[i], l1_p[i], l1_v[i], l1_decel[i], f_p[i], f_v[i],
            aggressive[i], lead_margin[i], follow_margin[i], prm, tol,
        )  # fmt: skip
        out[i] = r[0]
        if want_gaps:
            gaps[0, i] = r[9]
            gaps[1, i] = r[10]


@kernel(_PLAN_SIGNATURE)
def plan_kernel(
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, lead_margin, follow_margin, a_a, a_d,
    a_y, y_safe, tol, floats, flags,
):  # fmt: skip
    """Write :func:`~.evasion.evasion_parts` for each row: ``floats`` ``(10, n)`` in the order of
    :data:`FLOAT_PARTS`, ``flags`` ``(5, n)`` in that of :data:`BOOL_PARTS`. Inputs as :func:`exists_kernel`'s."""
    for i in range(floats.shape[1]):
        f, b = _plan_parts(
            ego_py[i], ego_vy[i], ego_px[i], ego_vx[i], l1_p[i], l1_v[i], l1_decel[i], f_p[i], f_v[i], aggressive[i],
            lead_margin[i], follow_margin[i], a_a, a_d, a_y, y_safe, tol,
        )  # fmt: skip
        for j in range(10):
            floats[j, i] = f[j]
        for j in range(5):
            flags[j, i] = b[j]


def _flat(args, shape):
    n = math.prod(shape)
    flat = []
    for j, a in enumerate(args):
        a = np.asarray(a, dtype=np.bool_ if j == 9 else np.float64)
        flat.append(np.broadcast_to(a, (n,)) if a.size == 1 else np.broadcast_to(a, shape).reshape(-1))
    return n, flat


def run(args, shape, params, tol: float, want_gaps: bool = False):
    """:func:`exists_kernel` on ``evasion_core``'s argument tuple (arrays broadcastable to ``shape``).

    Returns ``exists`` (bool, ``shape``) and, with ``want_gaps``, ``(lead_gap, follow_gap)`` as a ``(2, n)`` array
    (``n`` the number of elements)."""
    n, flat = _flat(args, shape)
    out = np.empty(n, dtype=np.bool_)
    gaps = np.empty((2, n if want_gaps else 0))
    exists_kernel(*flat, params.a_x_a, params.a_x_d, params.a_y_m, params.y_safe, tol, out, gaps)
    out = out.reshape(shape)
    return (out, gaps) if want_gaps else out


def run_plan(args, shape, params, tol: float):
    """:func:`plan_kernel` on ``evasion_core``'s argument tuple: ``(exists, parts)`` as ``evasion_core`` returns
    them, every array of ``shape``."""
    n, flat = _flat(args, shape)
    floats = np.empty((len(FLOAT_PARTS), n))
    flags = np.empty((len(BOOL_PARTS), n), dtype=np.bool_)
    plan_kernel(*flat, params.a_x_a, params.a_x_d, params.a_y_m, params.y_safe, tol, floats, flags)
    parts = {name: floats[j].reshape(shape) for j, name in enumerate(FLOAT_PARTS)}
    parts.update((name, flags[j].reshape(shape)) for j, name in enumerate(BOOL_PARTS[1:], start=1))
    return flags[0].reshape(shape), parts
