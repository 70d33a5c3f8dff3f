"""The compiled closed loop's held evasion plan over one period (numba, extra ``fast``; used by :mod:`._fast_loop`):
loops and indexing only.

No formula lives here. The plan's knots and its state at each come from the shield's own period
(:func:`safelane.shield._fast_period.period_row`); :func:`_motion_max` is
:func:`~.kinematics.extrema`' maximum, a walk over the knots with :func:`~.kinematics.vertex_extrema`. The loop's
tables are the NumPy path's, bit for bit, aborts included (``tests/test_fast_loop.py``).
"""

from __future__ import annotations

import numba
import numpy as np

from ..safety import _compile
from ..safety._backend import SCALAR
from ..safety._fast_base import _max
from .kinematics import piece_acc, vertex_extrema

_compile.register_rows()

_INF = np.inf


@numba.njit(inline="always")
def _motion_max(t, x, v):
    """``kinematics.extrema(m)[1]`` of one motion's knots: the largest knot value, then the largest vertex inside a
    segment, in its order of evaluation."""
    hi = x[0]
    for j in range(1, t.shape[0]):
        hi = _max(hi, x[j])
    top = -_INF
    for j in range(t.shape[0] - 1):
        span = t[j + 1] - t[j]
        top = _max(top, vertex_extrema(SCALAR, x[j], v[j], piece_acc(SCALAR, v[j], v[j + 1], span), span)[1])
    return _max(hi, top)
