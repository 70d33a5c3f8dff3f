"""Exactness of the simulator's motion and continuous-time collision checks (issue 3, item 3).

The reference steps time at 1 ms, splitting a step at every instant where the acceleration changes (event
location), and integrates each sub-step exactly (``x += v h + a h²/2``, cut short where a braking vehicle comes
to rest). It knows nothing of knots, stop times or ``Motion``; its only error is round-off, so the simulator
must match it to 1e-9.
"""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from safelane import Params
from safelane._motion import advance
from safelane.safety import plan_evasion
from safelane.safety._backend import ARRAY
from safelane.shield.decide import plan_motion
from safelane.sim.checks import ego_checks, lane_checks, stop_pair_extrema
from safelane.sim.kinematics import (
    Fleet,
    Motion,
    crossing_knots,
    extrema,
    gap_extrema,
    windowed_gap_extrema,
)
from sim_scenarios import mid_period_contact

PARAMS = Params()
H = 1e-3  # reference step [s]
TOL = 1e-9


def stepped(x0, v0, acc_of, t_end, events=(), clamp=True, h=H):
    """Reference trajectory of one vehicle: ``(times, x, v)`` on the 1 ms grid plus ``events``.

    ``acc_of(t)`` is the acceleration just after ``t`` (constant between consecutive grid times / events);
    ``clamp``: a braking vehicle stops and stays at rest (longitudinal); ``False`` for lateral motion.
    """
    grid = np.arange(0.0, t_end, h)
    nodes = np.unique(np.concatenate([grid, [t_end], [e for e in events if 0.0 < e < t_end]]))
    xs, vs = [x0], [v0]
    x, v = x0, v0
    for t0, t1 in itertools.pairwise(nodes):
        a = acc_of(0.5 * (t0 + t1))
        tau = t1 - t0
        if clamp and a < 0.0 and v + a * tau <= 0.0:
            s = v / -a
            x, v = x + v * s + 0.5 * a * s * s, 0.0
        elif clamp and v <= 0.0 and a <= 0.0:
            v = 0.0
        else:
            x, v = x + v * tau + 0.5 * a * tau * tau, v + a * tau
        xs.append(x)
        vs.append(v)
    return nodes, np.array(xs), np.array(vs)


# --- constant acceleration, with stopping ------------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(
    x=st.floats(-100.0, 100.0),
    v=st.floats(0.0, 35.0),
    a=st.one_of(st.just(0.0), st.floats(-8.0, -1e-3), st.floats(1e-3, 2.5)),
    dt=st.sampled_from([0.1, 0.5, 2.0]),
)
def test_advance_and_constant_motion_match_stepped_reference(x, v, a, dt):
    times, x_ref, v_ref = stepped(x, v, lambda t: a, dt)
    x1, v1 = advance(x, v, a, dt)
    assert abs(x1 - x_ref[-1]) <= TOL and abs(v1 - v_ref[-1]) <= TOL
    m = Motion.constant(x, v, a, dt)
    xq, vq = m.at(times)
    np.testing.assert_allclose(xq, x_ref, rtol=0, atol=TOL)
    np.testing.assert_allclose(vq, v_ref, rtol=0, atol=TOL)
    assert (vq >= 0.0).all()


def test_stop_inside_the_period_matches_reference_and_never_reverses():
    # 0.3 m/s braking at 8 m/s² stops after 37.5 ms of a 100 ms period and then stays put.
    x0, v0, a, dt = 5.0, 0.3, -8.0, 0.1
    times, x_ref, v_ref = stepped(x0, v0, lambda t: a, dt)
    m = Motion.constant(x0, v0, a, dt)
    xq, vq = m.at(times)
    np.testing.assert_allclose(xq, x_ref, rtol=0, atol=TOL)
    np.testing.assert_allclose(vq, v_ref, rtol=0, atol=TOL)
    assert m.t[1] == pytest.approx(0.0375)
    assert xq[-1] == pytest.approx(x0 + v0 * v0 / 16.0, abs=1e-12) and vq[-1] == 0.0
    assert advance(x0, v0, a, dt) == pytest.approx((x0 + v0 * v0 / 16.0, 0.0), abs=1e-12)


def test_batched_advance_matches_elementwise():
    rng = np.random.default_rng(0)
    x, v, a = rng.uniform(-50, 50, (2, 3)), rng.uniform(0, 35, (2, 3)), rng.uniform(-8, 2.5, (2, 3))
    x1, v1 = advance(x, v, a, 0.5)
    assert x1.shape == v1.shape == (2, 3)
    for idx in np.ndindex(2, 3):
        assert (x1[idx], v1[idx]) == advance(x[idx], v[idx], a[idx], 0.5)


def test_free_motion_is_not_clamped():
    m = Motion.free(1.0, 0.5, -1.5, 1.0)  # lateral: speed goes negative (heading home), no stop
    times, y_ref, vy_ref = stepped(1.0, 0.5, lambda t: -1.5, 1.0, clamp=False)
    yq, vyq = m.at(times)
    np.testing.assert_allclose(yq, y_ref, rtol=0, atol=TOL)
    np.testing.assert_allclose(vyq, vy_ref, rtol=0, atol=TOL)
    assert vyq[-1] == pytest.approx(-1.0)


# --- an abort: executing a verified evasion plan, switches inside periods ----------------------------------------


def _plan_acc(plan, i):
    """Longitudinal and lateral acceleration of plan ``i`` as functions of time since the plan's state,
    from its switch times (the accelerate–brake–follow profile and the lateral bang-bang)."""
    p = plan.take(i)
    T, u, t2 = float(p.t_y_f), float(p.t_x1), float(p.t_brake_end)
    l1_stop = float(p.l1_v / p.l1_decel) if p.l1_decel > 0 else np.inf

    def lon(t):
        if t >= T:
            return 0.0  # back in its own lane: the plan holds the speed reached
        if t < u:
            return PARAMS.a_x_a
        if t < t2:
            return -PARAMS.a_x_d
        return -float(p.l1_decel) if (p.follows_leader and t < l1_stop) else 0.0

    def lat(t):
        if t < p.t_y_switch:
            return float(p.y_acc_1)
        return float(p.y_acc_2) if t < p.t_y_end else 0.0

    return lon, lat, (T, u, t2, l1_stop, float(p.t_y_switch), float(p.t_y_end))


def _abort_plans():
    """Feasible evasion plans from mid-lane-change states whose longitudinal profiles have all the phases."""
    rng = np.random.default_rng(3)
    n = 400
    plan = plan_evasion(
        np.zeros(n),
        rng.uniform(1.0, 3.0, n),
        rng.uniform(0.5, 32.0, n),
        rng.uniform(-0.5, 1.2, n),
        rng.uniform(8.0, 40.0, n),
        rng.uniform(0.0, 32.0, n),
        rng.uniform(0.5, 8.0, n),
        -rng.uniform(15.0, 40.0, n),
        rng.uniform(10.0, 30.0, n),
        rng.uniform(size=n) < 0.5,
        PARAMS,
    )
    keep = np.flatnonzero(plan.feasible & (plan.t_y_f > 0.3))
    assert keep.size > 50
    return plan.take(keep)


def test_abort_plan_motion_matches_stepped_reference_across_switches():
    plan = _abort_plans()
    dt = PARAMS.dt
    checked_switch = checked_stop = 0
    for i in range(0, len(plan.t_y_f), 4):
        lon_acc, lat_acc, events = _plan_acc(plan, i)
        T, u = events[0], events[1]
        horizon = T + 0.3
        p = plan.take(i)
        times, x_ref, vx_ref = stepped(float(p.ego_px), float(p.ego_vx), lon_acc, horizon, events)
        _, y_ref, vy_ref = stepped(float(p.ego_py), float(p.ego_vy), lat_acc, horizon, events, clamp=False)
        # Periods of the abort: its first, one across the switch to braking, one across the end of braking
        # (a stop or the start of following L1) and the one in which the ego is back in its lane.
        t2 = events[2]
        ages = [0.0, min(max(u - 0.37 * dt, 0.0), T), min(max(t2 - 0.55 * dt, 0.0), T), max(T - 0.6 * dt, 0.0)]
        for age in ages:
            knots, px, vx, py, vy = plan_motion(plan.take(np.array([i])), np.array([age]), dt)
            lon, lat = Motion.from_samples(knots, px, vx), Motion.from_samples(knots, py, vy)
            inside = (times >= age - 1e-15) & (times <= age + dt + 1e-15)
            tq = times[inside] - age
            xq, vq = lon.at(tq[None, :])
            yq, vyq = lat.at(tq[None, :])
            np.testing.assert_allclose(xq[0], x_ref[inside], rtol=0, atol=TOL)
            np.testing.assert_allclose(vq[0], vx_ref[inside], rtol=0, atol=TOL)
            np.testing.assert_allclose(yq[0], y_ref[inside], rtol=0, atol=TOL)
            np.testing.assert_allclose(vyq[0], vy_ref[inside], rtol=0, atol=TOL)
            checked_switch += any(age < e < age + dt for e in events[1:3])
            checked_stop += bool((vq[0] == 0.0).any() and (vq[0] > 0.0).any())
    assert checked_switch >= 10 and checked_stop >= 1  # switches and stops inside a period were exercised


# --- exact gap extrema and the planted between-sample contact ----------------------------------------------------


def test_gap_extrema_match_dense_sampling():
    rng = np.random.default_rng(1)
    n, dt = 600, 0.5
    behind = Motion.constant(rng.uniform(-10, 0, n), rng.uniform(0, 35, n), rng.uniform(-8, 2.5, n), dt)
    ahead = Motion.constant(rng.uniform(0, 10, n), rng.uniform(0, 35, n), rng.uniform(-8, 2.5, n), dt)
    lo, hi = gap_extrema(behind, ahead)
    tq = np.linspace(0.0, dt, 2001)
    d = ahead.at(np.broadcast_to(tq, (n, tq.size)))[0] - behind.at(np.broadcast_to(tq, (n, tq.size)))[0]
    # Exact extrema bound every sample, and the densest sample is within the curvature bound of them.
    assert (lo <= d.min(1) + 1e-12).all() and (hi >= d.max(1) - 1e-12).all()
    step = tq[1] - tq[0]
    assert np.allclose(lo, d.min(1), rtol=0, atol=10.5 * step * step) and np.allclose(hi, d.max(1), atol=1e-3)
    ylo, yhi = extrema(behind)
    xs = behind.at(np.broadcast_to(tq, (n, tq.size)))[0]
    assert (ylo <= xs.min(1) + 1e-12).all() and (yhi >= xs.max(1) - 1e-12).all()


def test_stop_pair_extrema_equal_the_general_extrema_and_dense_sampling():
    """The closed form over the stop knots (used where someone stops inside the period) agrees with the general
    knot-merging extrema and bounds a dense sampling of the gap."""
    rng = np.random.default_rng(8)
    n, dt = 2000, 0.5
    cols = [(rng.uniform(-10, 10, n), rng.uniform(0, 6, n), rng.uniform(-8, 2.5, n)) for _ in range(2)]
    cols[0][1][::3] = 0.0  # some already at rest
    one, two = (Fleet.constant(x, v, a, dt) for x, v, a in cols)
    lo, hi = stop_pair_extrema(ARRAY, one.x, one.v, one.acc, one.t_stop, two.x, two.v, two.acc, two.t_stop, dt)
    m1, m2 = one.motion(slice(None)), two.motion(slice(None))
    ref_lo, ref_hi = gap_extrema(m1, m2)
    assert ((one.t_stop < dt) & (two.t_stop < dt)).sum() > 50  # both stop inside the period, often
    np.testing.assert_allclose(lo, ref_lo, rtol=0, atol=1e-12)
    np.testing.assert_allclose(hi, ref_hi, rtol=0, atol=1e-12)
    tq = np.broadcast_to(np.linspace(0.0, dt, 2001), (n, 2001))
    d = m2.at(tq)[0] - m1.at(tq)[0]
    assert (lo <= d.min(1) + 1e-12).all() and (hi >= d.max(1) - 1e-12).all()


def test_continuous_check_finds_contact_that_period_end_samples_miss():
    length = PARAMS.vehicle_length
    behind, ahead = mid_period_contact(PARAMS.dt, length)
    ends = ahead.x[..., [0, -1]] - behind.x[..., [0, -1]]
    assert (ends > length).all()  # sampling at the period's ends sees no contact …
    lo, _ = gap_extrema(behind, ahead)
    assert lo[0] < length  # … the exact minimum does
    assert lo[0] == pytest.approx(length + 0.01 - 10.5 * PARAMS.dt**2 / 8.0, abs=1e-12)
    _, xb, _ = stepped(0.0, 30.0, lambda t: -8.0, PARAMS.dt)
    _, xa, _ = stepped(length + 0.01, 30.0 - 0.525, lambda t: 2.5, PARAMS.dt)
    assert (xa - xb).min() == pytest.approx(lo[0], abs=1e-9)


@pytest.mark.parametrize(("crossing_s", "contact"), [(0.03, True), (0.09, False)])
def test_windowed_extrema_count_only_instants_inside_the_lateral_window(crossing_s, contact):
    # The ego enters the target lane's overlap zone at `crossing_s`; the gap dips below the length at 0.05 s.
    length, level, dt = PARAMS.vehicle_length, PARAMS.lane_width - PARAMS.vehicle_width, PARAMS.dt
    behind, ahead = mid_period_contact(dt, length)
    lat = Motion.free(np.array([level - 0.5 * crossing_s]), np.array([0.5]), np.array([0.0]), dt)
    knots = crossing_knots(lat, level)
    assert np.isclose(knots, crossing_s).any()
    lo, hi = windowed_gap_extrema(behind, ahead, lat, knots, level)
    assert bool(lo[0] < length) == contact
    full_lo, full_hi = gap_extrema(behind, ahead)
    assert lo[0] >= full_lo[0] - 1e-12 and hi[0] == pytest.approx(full_hi[0])
    never = Motion.free(np.array([0.0]), np.array([0.0]), np.array([0.0]), dt)
    lo_n, hi_n = windowed_gap_extrema(behind, ahead, never, crossing_knots(never, level), level)
    assert lo_n[0] == np.inf and hi_n[0] == -np.inf


def test_fleet_is_motion_constant_without_the_knots():
    """``Fleet.motion(idx)`` picks exactly the entries of the whole batch's motion, and ``end`` is its last knot."""
    rng = np.random.default_rng(5)
    dt = PARAMS.dt
    x, v, a = rng.uniform(-50, 50, (300, 4)), rng.uniform(0, 35, (300, 4)), rng.uniform(-8, 2.5, (300, 4))
    v[::7] = 0.0  # at rest, some "braking"
    v[::5, 1] = 0.3  # stopping inside the period
    fleet, full = Fleet.constant(x, v, a, dt), Motion.constant(x, v, a, dt)
    rows, cols = rng.integers(0, 300, 50), rng.integers(0, 4, 50)
    picked = fleet.motion(rows, cols)
    for f in ("t", "x", "v", "acc"):
        np.testing.assert_array_equal(getattr(picked, f), getattr(full, f)[rows, cols])
    np.testing.assert_array_equal(fleet.end[0], full.end[0])
    np.testing.assert_array_equal(fleet.end[1], full.end[1])
    assert (fleet.t_stop < dt).any() and (fleet.acc == 0.0).any()


def _ego_check_inputs(gap_l1_m, dip=True, ego_y=3.5):
    """One scenario: the ego (fully in the target lane at ``ego_y``) braking at 8 m/s² behind L1, which
    accelerates; the gap is ``gap_l1_m`` at both period ends and dips by 10.5 dt²/8 in between if ``dip``."""
    dt = PARAMS.dt
    closing = 10.5 * dt / 2.0 if dip else 0.0
    lon = Motion.constant(np.array([0.0]), np.array([30.0]), np.array([-8.0]), dt)
    lat = Motion.free(np.array([ego_y]), np.array([0.0]), np.array([0.0]), dt)
    x0 = np.array([[-40.0, gap_l1_m]])
    v0 = np.array([[30.0, 30.0 - closing]])
    acc = np.array([[0.0, 2.5 if dip else -8.0]])
    others = Fleet.constant(x0, v0, acc, dt)
    b = SimpleNamespace(valid=np.ones((1, 2), bool))
    s = SimpleNamespace(
        x=x0, v=v0, ego=(np.zeros(1), np.full(1, ego_y), np.full(1, 30.0), np.zeros(1)),
        min_gap_f=np.full(1, np.inf), min_gap_l1=np.full(1, np.inf),
    )  # fmt: skip
    levels = (PARAMS.y_safe + 1e-9, PARAMS.lane_width - PARAMS.vehicle_width)
    return b, s, lon, lat, others, levels


@pytest.mark.parametrize(
    ("gap", "dip", "ego_y", "expect"),
    [
        (PARAMS.vehicle_length + 0.01, True, 3.5, (True, True)),  # contact only between samples
        (PARAMS.p_m + 0.01, True, 3.5, (False, True)),  # p_m violated only between samples
        (PARAMS.p_m + 0.01, False, 3.5, (False, False)),  # same gap, no dip: clean
        (PARAMS.vehicle_length + 0.01, True, 0.0, (False, False)),  # ego in its own lane: nothing counts
    ],
)
def test_ego_checks_catch_between_sample_contact_and_violation(gap, dip, ego_y, expect):
    b, s, lon, lat, others, (conflict, overlap) = _ego_check_inputs(gap, dip, ego_y)
    collided, violated, _, min_gap_l1 = ego_checks(b, PARAMS, s, lon, lat, others, conflict, overlap)
    assert (bool(collided[0]), bool(violated[0])) == expect
    if ego_y > conflict:
        assert min_gap_l1[0] == pytest.approx(gap - 10.5 * PARAMS.dt**2 / 8.0 if dip else gap, abs=1e-12)


@pytest.mark.parametrize(
    ("gap", "speeds", "expect"),
    [
        (PARAMS.p_m + 0.5, (0.0, 0.0), (False, False)),  # both at rest beyond the margin: skipped, clean
        (PARAMS.p_m - 0.5, (0.0, 0.0), (False, True)),  # both at rest inside the margin: still a violation
        (PARAMS.vehicle_length - 0.5, (0.0, 0.0), (True, True)),  # … and overlap is a collision
        (PARAMS.p_m + 0.05, (20.0, 19.0), (False, True)),  # closing at 1 m/s: the margin is crossed in the period
    ],
)
def test_lane_checks_between_target_lane_vehicles(gap, speeds, expect):
    x = np.asfortranarray([[0.0, gap]])
    v = np.asfortranarray([list(speeds)])
    others = Fleet.constant(x, v, np.zeros((1, 2), order="F"), PARAMS.dt)
    b = SimpleNamespace(valid=np.ones((1, 2), bool), human=np.zeros((1, 2), bool))
    collided, violated, min_ratio = lane_checks(b, PARAMS, others)
    assert (bool(collided[0]), bool(violated[0])) == expect
    # The smallest gap over the margin: the gap at the period's end (constant speeds, the pair closes or rests).
    end_gap = gap + (speeds[1] - speeds[0]) * PARAMS.dt
    assert min_ratio[0] == pytest.approx(min(gap, end_gap) / PARAMS.p_m, abs=1e-12)
