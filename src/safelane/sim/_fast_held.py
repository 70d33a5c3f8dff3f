"""The compiled loop's one-vehicle motion and the held evasion plan's period (numba, extra ``fast``; used by
:mod:`._fast_loop`).

``_fleet`` is ``kinematics.Fleet.constant`` for one vehicle; ``_plan_sample`` is ``EvasionPlan.state`` for a plan held
as the loop's :data:`~._fast_loop.PLAN` values; ``_plan_motion`` is ``decide.plan_motion`` with
``Motion.from_samples`` (the period an aborting ego executes); ``_motion_max`` is ``kinematics.extrema``' maximum.
Each writes its NumPy original's expressions in their evaluation order (``tests/test_fast_loop.py`` compares the
loop's tables with the NumPy path's, aborts included).
"""

from __future__ import annotations

import numba
import numpy as np

from ..safety._fast import _ego_position, _ego_speed, _lateral_state
from ..safety._fast_base import _max, _min, _stop_time

_INF = np.inf


@numba.njit(inline="always")
def _clip(a, lo, hi):  # np.clip
    return _min(_max(a, lo), hi)


@numba.njit(inline="always")
def _fleet(x, v, a, dt):  # kinematics.Fleet.constant for one vehicle: (acc, t_stop, x_end, v_end)
    ts = _min(v / -a, dt) if a < 0.0 else dt
    if ts <= 0.0:
        a, ts = 0.0, dt
    xs = x + v * ts + 0.5 * a * ts * ts
    vs = 0.0 if ts < dt else _max(v + a * ts, 0.0)
    return a, ts, xs, vs


@numba.njit(error_model="numpy", nogil=True)
def _plan_sample(tq, plan, follows, a_a, a_d):
    """``EvasionPlan.state`` at ``tq`` of a plan held as :data:`PLAN` values (no own-lane leader): ``(px, py, vx,
    vy)``."""
    p, py0, v, vy0, p1, v1, a1, u, V, t2, T, t_1, acc_1, acc_2, t_end = plan
    tt = _min(tq, T)
    l1_stop = _stop_time(v1, a1)
    px = _ego_position(tt, p, v, u, V, t2, follows, p1, v1, a1, a_a, a_d, l1_stop)
    vx = _ego_speed(tt, v, u, V, t2, follows, v1, a1, a_a, a_d)
    px = px + vx * _max(tq - tt, 0.0)
    y, vy = _lateral_state(tq, py0, vy0, t_1, acc_1, acc_2, t_end)
    return px, y, vx, vy


@numba.njit(error_model="numpy", nogil=True)
def _plan_motion(plan, follows, age, dt, a_a, a_d, kt, kx, kv, ky, kvy, kax, kay):
    """``decide.plan_motion`` and ``Motion.from_samples`` of one held plan on ``[age, age + dt]``: the 8 knots into
    ``kt``, the samples into ``kx, kv, ky, kvy``, the segment accelerations into ``kax, kay``."""
    l1_v, l1_decel = plan[5], plan[6]
    l1_stop = l1_v / l1_decel if l1_decel > 0.0 else _INF
    kt[0] = 0.0
    kt[1] = _clip(plan[7] - age, 0.0, dt)  # t_x1
    kt[2] = _clip(plan[9] - age, 0.0, dt)  # t_brake_end
    kt[3] = _clip(l1_stop - age, 0.0, dt)
    kt[4] = _clip(plan[10] - age, 0.0, dt)  # t_y_f
    kt[5] = _clip(plan[11] - age, 0.0, dt)  # t_y_switch
    kt[6] = _clip(plan[14] - age, 0.0, dt)  # t_y_end
    kt[7] = dt
    kt.sort()
    for j in range(8):
        kx[j], ky[j], kv[j], kvy[j] = _plan_sample(age + kt[j], plan, follows, a_a, a_d)
    for j in range(7):
        span = kt[j + 1] - kt[j]
        kax[j] = (kv[j + 1] - kv[j]) / span if span > 0.0 else 0.0
        kay[j] = (kvy[j + 1] - kvy[j]) / span if span > 0.0 else 0.0


@numba.njit(inline="always")
def _motion_max(t, x, v):  # kinematics.extrema(m)[1]
    hi = x[0]
    for j in range(1, t.shape[0]):
        hi = _max(hi, x[j])
    top = -_INF
    for j in range(t.shape[0] - 1):
        span = t[j + 1] - t[j]
        ra = (v[j + 1] - v[j]) / span if span > 0.0 else 0.0
        tau = -v[j] / ra if ra != 0.0 else -1.0
        if tau > 0.0 and tau < span and ra < 0.0:
            top = _max(top, x[j] + v[j] * tau + 0.5 * ra * tau * tau)
    return _max(hi, top)
