"""Units of RSS's closed forms and of its lane-change rule (``baselines/rss.py``, ``baselines/rss_rule.py``) against
independent computations: the ego's state after one period against a fine time-stepped integration, the others'
predictions against hand-written kinematics, the stated braking pattern above ``max_speed_on_acceleration`` by hand.
(A sample of the ``rss`` mutation group found these unchecked.)"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.baselines.rss import RssParams, pair_check, stated_braking_longitudinal
from safelane.baselines.rss_rule import ahead_after_core, ego_after_core, follower_after_core
from safelane.safety._backend import ARRAY


def _stepped(x, v, a, dt, stops=True, steps=20_000):
    """Constant acceleration ``a`` for ``dt`` (speed held at 0 once it reaches it, where ``stops``): small steps."""
    h = dt / steps
    for _ in range(steps):
        v_next = max(v + a * h, 0.0) if stops else v + a * h
        x += 0.5 * (v + v_next) * h
        v = v_next
    return x, v


@pytest.mark.parametrize(("vx", "ax", "vy", "ay"), [(20.0, 1.5, 0.3, 1.2), (0.2, -6.0, -0.4, -2.0),
                                                    (30.0, -3.0, 0.0, 2.6), (5.0, 0.0, 1.0, -0.7)])  # fmt: skip
def test_ego_after_one_period_is_the_integrated_motion(vx, ax, vy, ay):
    prm = Params()
    ex, ey, evx, evy = ego_after_core(ARRAY, np.array([10.0]), np.array([0.5]), np.array([vx]), np.array([vy]),
                                      np.array([ax]), np.array([ay]), prm.dt)  # fmt: skip
    x_ref, v_ref = _stepped(10.0, vx, ax, prm.dt)
    y_ref, vy_ref = _stepped(0.5, vy, ay, prm.dt, stops=False)  # (laterally free: no stop)
    assert abs(ex[0] - x_ref) < 1e-6 and abs(evx[0] - v_ref) < 1e-9
    assert abs(ey[0] - y_ref) < 1e-9 and abs(evy[0] - vy_ref) < 1e-9


def test_the_others_are_predicted_at_their_worst_over_the_period():
    """A vehicle ahead brakes at its ``brake_max`` (to rest), F accelerates at ``accel_max``: each verdict is
    ``pair_check``'s on the states the period's hand-written kinematics give."""
    prm, rss = Params(), RssParams()
    rng = np.random.default_rng(3)
    n = 400
    ego = [np.zeros(n), rng.uniform(0.0, 3.5, n), rng.uniform(10.0, 30.0, n), rng.uniform(-1.0, 1.0, n)]
    x, v, brake = rng.uniform(2.0, 60.0, n), rng.uniform(0.0, 30.0, n), rng.uniform(0.5, 8.0, n)
    safe, lon_ok = ahead_after_core(ARRAY, *ego, x, v, prm.lane_width, brake, rss, prm.vehicle_length,
                                    prm.vehicle_width, prm.dt)  # fmt: skip
    stop = np.minimum(v / brake, prm.dt)
    x1, v1 = x + v * stop - 0.5 * brake * stop**2, np.maximum(v - brake * prm.dt, 0.0)
    ref = pair_check(*ego, x1, prm.lane_width, v1, 0.0, rss, prm, brake)
    np.testing.assert_array_equal(safe, ref[0])
    np.testing.assert_array_equal(lon_ok, ref[1] | ~(x1 > ego[0]))
    assert safe.any() and not safe.all() and not lon_ok.all()
    f_x, f_v = -rng.uniform(2.0, 60.0, n), rng.uniform(0.0, 30.0, n)
    to_f = follower_after_core(ARRAY, *ego, f_x, f_v, prm.lane_width, rss, prm.vehicle_length, prm.vehicle_width,
                               prm.dt)  # fmt: skip
    f1 = f_x + f_v * prm.dt + 0.5 * rss.accel_max * prm.dt**2
    ref_f = pair_check(*ego, f1, prm.lane_width, f_v + rss.accel_max * prm.dt, 0.0, rss, prm)
    np.testing.assert_array_equal(to_f, ref_f[0])
    assert to_f.any() and not to_f.all()


def test_stated_braking_above_the_acceleration_speed_limit_does_not_accelerate():
    """Above ``max_speed_on_acceleration`` the rear vehicle keeps its speed during the response time (ad-rss: the
    speed limit is ``max(max_speed, v)``): ``v ρ + v² / (2 brake_min)``; below it, it accelerates up to the limit."""
    v, rho, acc, brake = 120.0, 1.0, 3.5, 4.0
    assert stated_braking_longitudinal(v, rho, acc, brake, max_speed=100.0) == pytest.approx(
        v * rho + v * v / (2 * brake), rel=1e-12)
    # 99 m/s reaches the 100 m/s limit after 1/3.5 s, then holds it for the rest of ρ
    v, t_acc = 99.0, 1.0 / 3.5
    expect = v * t_acc + 0.5 * acc * t_acc**2 + 100.0 * (rho - t_acc) + 100.0**2 / (2 * brake)
    assert stated_braking_longitudinal(v, rho, acc, brake, max_speed=100.0) == pytest.approx(expect, rel=1e-12)
