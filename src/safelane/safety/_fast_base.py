"""The scalar building blocks of the compiled kernels (numba; extra ``fast``): NaN-propagating ``min``/``max`` as
``np.minimum``/``np.maximum``, the guarded square root, stop time and distance of :mod:`._backend` and
:func:`~.chain.braked_position`, each written in the NumPy path's evaluation order (see :mod:`._fast`), and the
array types of the kernels' explicit signatures."""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types

_INF = math.inf

# One explicit signature (compiled at import, or loaded from the cache): read-only 1-D arrays of any layout, so
# contiguous inputs, broadcast scalars (stride 0) and read-only views all take the same machine code.
_F = types.Array(types.float64, 1, "A", readonly=True)
_B = types.Array(types.bool_, 1, "A", readonly=True)


@numba.njit(inline="always")
def _max(a, b):
    return a if (a >= b or a != a) else b  # NaN propagates (np.maximum)


@numba.njit(inline="always")
def _min(a, b):
    return a if (a <= b or a != a) else b  # NaN propagates (np.minimum)


@numba.njit(inline="always")
def _sqrt(x):
    return math.sqrt(_max(x, 0.0))  # _Array.sqrt


@numba.njit(inline="always")
def _nan_to_neg(x):
    return x if x == x else -1.0


@numba.njit(inline="always")
def _stop_time(v, a):
    if a > 0.0:
        return v / a
    return _INF if v > 0.0 else 0.0


@numba.njit(inline="always")
def _stop_dist(v, a):
    if a > 0.0:
        return v * v / (2.0 * a)
    return _INF if v > 0.0 else 0.0


@numba.njit(inline="always")
def _braked(p, v, decel, t, t_stop):  # chain.braked_position
    tt = _min(t, t_stop)
    return p + v * tt - 0.5 * decel * tt * tt


def readonly(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a`` (what the signatures' read-only array types take; the caller's array is untouched)."""
    view = a.view()
    view.flags.writeable = False
    return view
