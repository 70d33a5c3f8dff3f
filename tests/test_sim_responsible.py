"""The responsible-follower acceleration: its closed form safe and maximal against the full check, on random,
simulator-like and adversarial rows, and equal to an independent time-sampled reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from safelane import Params
from safelane.safety.responsible import final_stop_accel, responsible_accel, responsible_bounds, responsible_ok

PRM = Params()


def _random_rows(n: int, seed: int):
    rng = np.random.default_rng(seed)
    slack, v_f, v_l = rng.uniform(-2, 40, n), rng.uniform(0, 35, n), rng.uniform(0, 35, n)
    lead, wanted = rng.uniform(0, PRM.a_x_d, n), rng.uniform(-PRM.a_x_d, PRM.a_x_a, n)
    lead[::7], v_f[::11], v_l[::13] = 0.0, 0.0, 0.0
    return wanted, slack, v_f, v_l, lead


@pytest.mark.parametrize("seed", range(3))
def test_responsible_accel_is_safe_and_maximal(seed):
    wanted, slack, v_f, v_l, lead = _random_rows(100_000, seed)
    a = responsible_accel(wanted, slack, v_f, v_l, lead, PRM)
    assert (a <= wanted + 1e-12).all() and (a >= -PRM.a_x_d - 1e-12).all()
    floor = a <= -PRM.a_x_d + 1e-12
    assert responsible_ok(a, slack, v_f, v_l, lead, PRM)[~floor].all()
    # Maximal to within 1e-7 m/s² (the closed form is applied 1e-9 on the safe side), unless the planner's own
    # wish was the cap; where the answer is the floor, nothing above it is safe either.
    larger = responsible_ok(np.minimum(a + 1e-7, wanted), slack, v_f, v_l, lead, PRM)
    assert not (larger & (a < wanted - 1e-12)).any()


def _near_rows(n: int, seed: int):
    """Followers close behind, as in the simulator: every bound binds somewhere."""
    rng = np.random.default_rng(seed)
    slack, v_f = rng.uniform(-0.5, 12, n), rng.uniform(0, 32, n)
    v_l = np.clip(v_f + rng.normal(0, 4, n), 0, None)
    lead, wanted = rng.uniform(0, PRM.a_x_d, n), rng.uniform(-PRM.a_x_d, PRM.a_x_a, n)
    lead[::3] = PRM.a_x_d
    return wanted, slack, v_f, v_l, lead


@pytest.mark.parametrize("seed", range(3))
def test_every_bound_binds_and_the_answer_is_maximal(seed):
    wanted, slack, v_f, v_l, lead = _near_rows(100_000, seed)
    bounds = responsible_bounds(slack, v_f, v_l, lead, PRM)
    names = ["wanted", *bounds]
    binding = np.argmin(np.stack([wanted, *bounds.values()]), 0)
    counts = dict(zip(names, np.bincount(binding, minlength=len(names)), strict=True))
    counts.pop("end")  # binds alone only in ties (see responsible_bounds)
    assert min(counts.values()) > 100, counts
    a = responsible_accel(wanted, slack, v_f, v_l, lead, PRM)
    floor = a <= -PRM.a_x_d + 1e-12
    assert responsible_ok(a, slack, v_f, v_l, lead, PRM)[~floor].all()
    assert not (responsible_ok(np.minimum(a + 1e-7, wanted), slack, v_f, v_l, lead, PRM) & (a < wanted - 1e-12)).any()


def _grid(lo, hi):
    corners = [lo, hi, min(max(0.0, lo), hi)] + ([-0.0] if lo <= 0.0 <= hi else [])
    return st.one_of(st.sampled_from(corners), st.floats(lo, hi).map(lambda x: round(x, 6)))


@settings(max_examples=3000, deadline=None)
@example(wanted=2.5, slack=-0.0, v_f=9.25, v_l=9.0, lead=0.0)  # found by CI: −0.0 slack flipped the vertex's sign
@given(_grid(-PRM.a_x_d, PRM.a_x_a), _grid(-1.0, 60.0), _grid(0.0, 40.0), _grid(0.0, 40.0), _grid(0.0, PRM.a_x_d))
def test_closed_form_is_safe_and_maximal_on_adversarial_rows(wanted, slack, v_f, v_l, lead):
    """Ties and corners (zero slack, speeds or decelerations; equal speeds): safe, and nothing 1e-7 larger is."""
    row = [np.array([x]) for x in (slack, v_f, v_l, lead)]
    a = float(responsible_accel(np.array([wanted]), *row, PRM)[0])
    if a > -PRM.a_x_d:
        assert responsible_ok(np.array([a]), *row, PRM)[0]
    if a < wanted - 2e-9:
        assert not responsible_ok(np.array([min(a + 1e-7, wanted)]), *row, PRM)[0]


def _sampled_min_gap(a, slack, v_f, v_l, lead, dt, brake, t):
    """Gap minus margin at the sample instants ``t``: follower at ``a`` for ``dt`` then ``brake``, leader at
    ``-lead``, both stopping at rest (plain kinematics, evaluated pointwise)."""

    def position(v0, acc, time):
        stop = np.where(acc < 0.0, v0 / np.where(acc < 0.0, -acc, 1.0), np.inf)
        s = np.minimum(time, stop)
        return v0 * s + 0.5 * acc * s * s

    x1, w = position(v_f, a, np.minimum(t, dt)), np.maximum(v_f + a * dt, 0.0)
    if np.any(v_f + a * dt < 0.0):
        w = np.where(v_f + a * dt < 0.0, 0.0, w)
    follower = np.where(t <= dt, x1, position(v_f, a, dt) + position(w, -brake, np.maximum(t - dt, 0.0)))
    leader = slack + position(v_l, -lead, t)
    return (leader - follower).min(-1)


def test_responsible_accel_agrees_with_a_sampled_reference():
    """Independent of every closed form: bisection on the minimum gap sampled on a fine time grid."""
    rng = np.random.default_rng(11)
    n = 300
    slack, v_f, v_l = rng.uniform(0.5, 30, n), rng.uniform(5, 35, n), rng.uniform(5, 35, n)
    lead, wanted = rng.uniform(0.5, PRM.a_x_d, n), rng.uniform(-PRM.a_x_d, PRM.a_x_a, n)
    dt, brake = PRM.dt, PRM.a_x_d
    horizon = max((v_l / lead).max(), 40.0 / brake + dt) + 1.0
    t = np.concatenate([np.linspace(0.0, dt, 2001), np.linspace(dt, horizon, 60_001)[1:]])[None, :]
    args = (slack[:, None], v_f[:, None], v_l[:, None], lead[:, None], dt, brake, t)
    lo, hi = np.full(n, -brake), wanted.copy()
    ok_hi = _sampled_min_gap(hi[:, None], *args) >= 0.0
    lo = np.where(ok_hi, hi, lo)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        ok = (_sampled_min_gap(mid[:, None], *args) >= 0.0) | ok_hi
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    a = responsible_accel(wanted, slack, v_f, v_l, lead, PRM)
    # Sampling can only miss a minimum (reference slightly optimistic): 1e-3 m/s² covers the grid spacing.
    np.testing.assert_allclose(a, lo, atol=1e-3)
    assert (a < wanted - 0.1).sum() > 50  # the bound binds in many rows


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
