"""Compiled responsible following (numba; extra ``fast``): :func:`responsible_kernel`, the bound over a batch, and
the row functions the simulator's and the shield's kernels call — each the one source of :mod:`.responsible`,
:func:`.chain.min_follow_decel` or :func:`safelane._motion.advance_core`, compiled on the float backend ``SCALAR``.

No formula lives here. The closed forms are backend-generic functions marked ``jitable`` (:mod:`._compile` registers
them); the same Python functions run on NumPy arrays in the uncompiled path. numba compiles without ``fastmath`` and
evaluates every expression in the source's order, ``SCALAR``'s ``minimum``/``maximum`` propagate NaN as NumPy's:
the same bits (``tests/test_fast_responsible.py``; the simulator's leaders, ``tests/test_fast_traffic.py``). Callers
compile with ``error_model="numpy"`` (a division by zero the source leaves unguarded is ``±inf`` or NaN, never an
exception; the row functions are inlined, so the caller's model applies).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types

from .._motion import advance_core
from . import _compile
from ._backend import SCALAR
from ._fast_base import _F, announce_compiles, kernel, readonly
from .chain import min_follow_decel
from .responsible import pair_min_gap_core, responsible_bound_core, responsible_ok_core

_compile.register_rows()
announce_compiles()

_RESPONSIBLE_SIGNATURE = types.void(*(_F,) * 5, types.float64, types.Array(types.float64, 1, "C"))


@numba.njit(error_model="numpy", nogil=True)
def _responsible_bound(slack, vf, vl, d, b, dt):
    """One row of :func:`~.responsible.responsible_bound_core` (brake ``b``)."""
    return responsible_bound_core(SCALAR, slack, vf, vl, d, b, dt)


@numba.njit(inline="always")
def _advance(x, v, a, dt):
    """One row of :func:`safelane._motion.advance_core`: ``(x', v')``."""
    return advance_core(SCALAR, x, v, a, dt)


@numba.njit(error_model="numpy", nogil=True)
def _pair_min_gap(slack, v_f, a_f, v_l, a_l, dt):
    """One row of :func:`~.responsible.pair_min_gap_core`."""
    return pair_min_gap_core(SCALAR, slack, v_f, a_f, v_l, a_l, dt)


@numba.njit(error_model="numpy", nogil=True)
def _min_follow_decel(slack, v_f, v_l, a_l, half, tol):
    """One row of :func:`~.chain.min_follow_decel` at tolerance ``tol``; ``half`` (``0.5 * tol``, which the
    function derives itself) is kept for the callers' signature."""
    return min_follow_decel(SCALAR, slack, v_f, v_l, a_l, tol)


@numba.njit(error_model="numpy", nogil=True)
def _responsible_ok(a, slack, v_f, v_l, lead_decel, brake, dt, tol, half, feas_tol):
    """One row of :func:`~.responsible.responsible_ok_core` with the chain link's tolerance ``feas_tol``; ``half``
    (``0.5 * feas_tol``, which :func:`~.chain.min_follow_decel` derives itself) is kept for the callers' signature."""
    return responsible_ok_core(SCALAR, a, slack, v_f, v_l, lead_decel, brake, dt, tol, feas_tol)


@kernel(_RESPONSIBLE_SIGNATURE)
def responsible_kernel(slack, v_f, v_l, lead_decel, brake, dt, out):
    """:func:`~.responsible.responsible_bound` per element (:func:`~.responsible.responsible_bound_core` on a row)
    — the same bits (``tests/test_fast_responsible.py``)."""
    for i in range(out.shape[0]):
        out[i] = responsible_bound_core(SCALAR, slack[i], v_f[i], v_l[i], lead_decel[i], brake[i], dt)


def responsible(slack, v_f, v_l, lead_decel, brake, dt: float) -> np.ndarray:
    """:func:`responsible_kernel` on arrays broadcast to one shape; returns that shape."""
    arrays = [np.asarray(x, dtype=np.float64) for x in (slack, v_f, v_l, lead_decel, brake)]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    n = math.prod(shape)
    # Scalars with stride 0, arrays of the full shape as they are (read-only views: the signature takes any layout).
    flat = [np.broadcast_to(a.reshape(-1), (n,)) if a.size == 1 else np.broadcast_to(a, shape).reshape(-1)
            for a in arrays]  # fmt: skip
    # Read-only views set explicitly: a view of an np.broadcast_arrays output (a column of one) would otherwise make
    # numba's typing read its deprecated "writeable with a warning" flag and emit NumPy's FutureWarning.
    flat = [readonly(f) for f in flat]
    out = np.empty(n)
    responsible_kernel(*flat, float(dt), out)
    return out.reshape(shape)
