"""The responsible-follower acceleration: safe, maximal, and its closed-form final-stop bound exact."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.sim.behaviours import final_stop_accel, responsible_accel, responsible_ok

PRM = Params()


def _random_rows(n: int, seed: int):
    rng = np.random.default_rng(seed)
    slack, v_f, v_l = rng.uniform(-2, 40, n), rng.uniform(0, 35, n), rng.uniform(0, 35, n)
    lead, wanted = rng.uniform(0, PRM.a_x_d, n), rng.uniform(-PRM.a_x_d, PRM.a_x_a, n)
    lead[::7], v_f[::11], v_l[::13] = 0.0, 0.0, 0.0
    return wanted, slack, v_f, v_l, lead


def test_responsible_accel_is_safe_and_maximal():
    wanted, slack, v_f, v_l, lead = _random_rows(50_000, 0)
    a = responsible_accel(wanted, slack, v_f, v_l, lead, PRM)
    assert (a <= wanted + 1e-12).all() and (a >= -PRM.a_x_d - 1e-12).all()
    floor = a <= -PRM.a_x_d + 1e-12
    assert responsible_ok(a, slack, v_f, v_l, lead, PRM)[~floor].all()
    # Nothing noticeably larger is safe: 0.003 m/s² more (the bisection's resolution is ~0.0022) fails,
    # unless the planner's own wish was the cap.
    larger = responsible_ok(np.minimum(a + 0.003, wanted), slack, v_f, v_l, lead, PRM)
    assert (~larger | (a >= wanted - 1e-12))[~floor].all()


def _stop_position(v, a, dt, brake, substeps=20000):
    """Time-stepped stopping position: ``a`` for ``dt`` (stopping at rest), then ``brake`` until at rest."""
    x, speed, h = 0.0, v, dt / substeps
    for _ in range(substeps):
        step = max(speed + a * h, 0.0)
        x += 0.5 * (speed + step) * h
        speed = step
    return x + speed * speed / (2.0 * brake)


@pytest.mark.parametrize("seed", range(40))
def test_final_stop_accel_stops_exactly_at_the_leaders_stop(seed):
    rng = np.random.default_rng(seed)
    slack, v_f, v_l, lead = rng.uniform(0.5, 40), rng.uniform(0, 35), rng.uniform(0, 35), rng.uniform(0.5, 8)
    a = float(final_stop_accel(np.array([slack]), np.array([v_f]), np.array([v_l]), np.array([lead]), PRM)[0])
    leader_stop = slack + v_l * v_l / (2.0 * lead)
    assert _stop_position(v_f, a, PRM.dt, PRM.a_x_d) == pytest.approx(leader_stop, rel=1e-6, abs=1e-5)


def test_final_stop_accel_edge_cases():
    never_stops = final_stop_accel(np.array([10.0]), np.array([30.0]), np.array([30.0]), np.array([0.0]), PRM)
    too_close = final_stop_accel(np.array([-1.0]), np.array([30.0]), np.array([0.0]), np.array([5.0]), PRM)
    assert np.isposinf(never_stops[0]) and np.isneginf(too_close[0])
