"""The compiled closed loop's held evasion plan over one period (numba, extra ``fast``; used by :mod:`._fast_loop`):
loops and indexing only.

No formula lives here. :func:`_plan_motion` is :func:`~safelane.shield.decide.plan_motion` with
``Motion.from_samples`` for a plan held as the loop's :data:`~._fast_loop.PLAN` values: the knots and the plan's
state at each from the shield's own period (:func:`safelane.shield._fast_period.plan_knots`), then each segment's
accelerations (:func:`~.kinematics.piece_acc`), the same closed forms the NumPy path evaluates on arrays, compiled on
``SCALAR``. :func:`_motion_max` is
:func:`~.kinematics.extrema`' maximum, a walk over the knots with :func:`~.kinematics.vertex_extrema`. The loop's
tables are the NumPy path's, bit for bit, aborts included (``tests/test_fast_loop.py``).
"""

from __future__ import annotations

import numba
import numpy as np

from ..safety import _compile
from ..safety._backend import SCALAR
from ..safety._fast_base import _max
from ..safety.plan import PlanRecord
from ..shield._fast_period import plan_knots
from .kinematics import piece_acc, vertex_extrema

_compile.register_rows()

_INF = np.inf


@numba.njit(error_model="numpy", nogil=True)
def _plan_motion(plan, follows, age, dt, a_a, a_d, kt, kx, kv, ky, kvy, kax, kay):
    """``decide.plan_motion`` and ``Motion.from_samples`` of one held plan (:data:`~._fast_loop.PLAN` values, no
    own-lane leader: it follows L1 where ``follows``) on ``[age, age + dt]``: the 8 knots into ``kt``, the samples
    into ``kx, kv, ky, kvy``, the segment accelerations into ``kax, kay``."""
    held = PlanRecord(plan[0], plan[1], plan[2], plan[3], plan[7], plan[8], plan[9], follows, plan[10], plan[11],
                      plan[12], plan[13], plan[14], False)  # fmt: skip
    plan_knots(held, plan[4], plan[5], plan[6], age, dt, a_a, a_d, kt, kx, kv, ky, kvy)
    for j in range(7):
        span = kt[j + 1] - kt[j]
        kax[j] = piece_acc(SCALAR, kv[j], kv[j + 1], span)
        kay[j] = piece_acc(SCALAR, kvy[j], kvy[j + 1], span)


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
