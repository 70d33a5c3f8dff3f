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


def _verdict_by_hand(active, invalid, ok_chain, ok_f, ok_chain_h, ok_f_h):
    """The rule's order, as its module docstring states it: once complete, none; an RSS-safe proposal (never an
    invalid one); else an RSS-safe hesitation; else the proper response."""
    if not active:
        return False, False, False
    if not invalid and ok_chain and ok_f:
        return True, False, False
    if ok_chain_h and ok_f_h:
        return False, True, False
    return False, False, True


def test_the_verdict_follows_the_rules_order_on_every_combination():
    from itertools import product

    from safelane.baselines.rss_rule import verdict_core

    combos = np.array(list(product([False, True], repeat=6)))
    got = verdict_core(ARRAY, *combos.T)
    for row, p, h, r in zip(combos, *got, strict=True):
        assert (bool(p), bool(h), bool(r)) == _verdict_by_hand(*row), row


def test_the_lateral_command_of_each_behaviour():
    """Proceed: the proposal; hesitate: the hesitation; respond: back towards the original lane by the PD law
    (``-0.8 y - 1.6 v_y``, clipped to ``a_y_m``), braking laterally at ``lat_brake_min`` or more while still moving
    out; complete: the lane keeping's command."""
    from safelane.baselines.rss_rule import lateral_core

    a_y_m, lat_brake_min = 1.5, 0.8
    f, t = np.array([False]), np.array([True])
    one = lambda p, h, r, c, y, vy: float(lateral_core(ARRAY, p, h, r, c, np.array([0.7]), np.array([-0.3]),  # noqa: E731
                                                       np.array([0.05]), np.array([y]), np.array([vy]), a_y_m,
                                                       lat_brake_min)[0])  # fmt: skip
    assert one(t, f, f, f, 1.0, 0.5) == 0.7
    assert one(f, t, f, f, 1.0, 0.5) == -0.3
    assert one(f, f, f, t, 3.4, 0.0) == 0.05
    # responding, moving out slowly: the PD law asks -0.8 - 0.16 = -0.96, harder than lat_brake_min: as is
    assert one(f, f, t, f, 1.0, 0.1) == pytest.approx(-0.8 * 1.0 - 1.6 * 0.1)
    # responding, moving out, near the original lane: the PD law asks less than lat_brake_min: -lat_brake_min
    assert one(f, f, t, f, 0.1, 0.01) == -lat_brake_min
    # responding, already moving back: the PD law alone (here positive: it brakes the return), clipped to a_y_m
    assert one(f, f, t, f, 0.2, -0.9) == pytest.approx(-0.8 * 0.2 + 1.6 * 0.9)
    assert one(f, f, t, f, 0.2, -2.0) == a_y_m  # (-0.16 + 3.2, clipped)


def test_completion_is_the_centre_crossing_the_boundary_this_period():
    from safelane.baselines.rss_rule import completing_core

    prm = Params()
    y0 = prm.y_boundary - 0.05
    t, f = np.array([True]), np.array([False])
    crossing = completing_core(ARRAY, t, f, np.array([y0]), np.array([0.6]), np.array([0.0]), prm.dt, prm.y_boundary)
    assert crossing[0]  # 0.06 m this period
    short = completing_core(ARRAY, f, t, np.array([y0]), np.array([0.4]), np.array([0.0]), prm.dt, prm.y_boundary)
    assert not short[0]  # 0.04 m
    still = completing_core(ARRAY, f, f, np.array([y0]), np.array([0.6]), np.array([0.0]), prm.dt, prm.y_boundary)
    assert not still[0]  # a responding row never completes


def test_each_vehicle_ahead_gets_its_brake_max():
    """L1: the variant's worst case with V2X, else RSS's ``brake_max``; a connected leader behind L1: its chain bound
    with V2X; a non-connected one: RSS's; never below the floor."""
    from safelane.baselines.rss_rule import BRAKE_FLOOR_MPS2, chain_brake_core

    slots = np.arange(4)
    bounds = np.array([0.0, 0.5, 1.5, 2.5])
    with_v2x = chain_brake_core(ARRAY, slots, True, 2, bounds, 3.0, 8.0)
    np.testing.assert_array_equal(with_v2x, [3.0, 0.5, 8.0, 8.0])
    np.testing.assert_array_equal(chain_brake_core(ARRAY, slots, False, 2, bounds, 3.0, 8.0), [8.0] * 4)
    assert chain_brake_core(ARRAY, 0, True, 1, 0.0, 0.0, 8.0) == BRAKE_FLOOR_MPS2


def test_matched_parameters_and_their_vector():
    from safelane.baselines.rss import RSS_FIELDS, rss_vector

    prm = Params(a_x_a=2.0, a_x_d=7.0, a_y_m=1.2, dt=0.05)
    m = RssParams.matched(prm)
    assert (m.response_time_ego, m.response_time_other) == (0.05, 0.05)
    assert (m.accel_max, m.brake_min, m.brake_max, m.brake_min_correct) == (2.0, 7.0, 7.0, 7.0)
    assert (m.lat_accel_max, m.lat_brake_min) == (1.2, 1.2)
    assert m.lateral_fluctuation_margin == RssParams().lateral_fluctuation_margin
    vec = rss_vector(m)
    assert vec.tolist() == [getattr(m, name) for name in RSS_FIELDS] and len(RSS_FIELDS) == 10
    assert RSS_FIELDS[:5] == ("response_time_ego", "response_time_other", "accel_max", "brake_min", "brake_max")
