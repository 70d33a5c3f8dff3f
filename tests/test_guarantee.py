"""The safety guarantee's knife edges (issue: a p_m violation inside the assumptions).

* the minimal following deceleration at the margin (``slack = 0`` and round-off around it) against the
  independent bisection reference, and the chain bound's continuity there;
* the consistency invariant: for L(N+1) braking profiles inside the assumptions (switching at any instant, also
  inside a period) and leader tasks anywhere inside their promises, no leader violates its margin and no leader
  ever brakes harder than the bound the chain analysis gave it at any earlier time;
* L(N+1)'s switch inside a period integrated exactly;
* invalid nominal proposals never reach the state; the assumption monitor.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from reference import ref_min_follow_decel
from safelane import Params
from safelane.safety import leader_chain
from safelane.safety._backend import ARRAY, SCALAR
from safelane.safety.chain import min_follow_decel
from safelane.sim import SimConfig, paper_scenarios, simulate, simulate_batch
from safelane.sim.kinematics import Fleet
from safelane.sim.step import ClosedLoop
from safelane.sim.traffic import TrafficHooks, with_last_profile

PRM = Params()
BOUNDARY_SLACKS = [0.0, -0.0, 1e-15, -1e-15, 1e-300, -1e-12, -9e-10]


def _z_both(slack, v_f, v_l, a_l):
    """The library's z on both backends (they must agree)."""
    batched = float(min_follow_decel(ARRAY, np.array([slack]), np.array([v_f]), np.array([v_l]), np.array([a_l]))[0])
    scalar = float(min_follow_decel(SCALAR, slack, v_f, v_l, a_l))
    assert batched == scalar or (np.isinf(batched) and np.isinf(scalar))
    return batched


def _z_ref(slack, v_f, v_l, a_l):
    margin = PRM.p_m
    r = ref_min_follow_decel(*(np.array([x]) for x in (0.0, v_f, slack + margin, v_l, a_l, margin)), 1e6)
    return float(r.z[0])


@settings(max_examples=300, deadline=None)
@given(
    slack=st.sampled_from(BOUNDARY_SLACKS),
    v_l=st.floats(0.0, 40.0),
    dv=st.one_of(st.just(0.0), st.floats(-20.0, 0.0), st.floats(1e-3, 10.0)),
    a_l=st.one_of(st.just(0.0), st.floats(0.0, 8.0), st.just(8.0)),
)
@example(slack=0.0, v_l=30.0, dv=0.0, a_l=0.5)  # the state: exactly at the margin, same speed
@example(slack=-1e-15, v_l=30.0, dv=0.0, a_l=6.25)  # ... with round-off below zero
@example(slack=0.0, v_l=0.0, dv=0.0, a_l=8.0)  # both at rest at the margin
@example(slack=0.0, v_l=0.0, dv=0.0, a_l=0.0)
@example(slack=-9e-10, v_l=1.0591019335684353e-252, dv=0.0, a_l=8.0)  # v² underflows: 0/0 in the NumPy path
@example(slack=-9e-10, v_l=2.220446049250313e-16, dv=0.0, a_l=1.0)  # z = a_l exactly; the reference sees 0
def test_min_follow_decel_at_the_margin_matches_the_reference(slack, v_l, dv, a_l):
    v_f = max(v_l + dv, 0.0)
    z = _z_both(slack, v_f, v_l, a_l)
    ref = _z_ref(slack, v_f, v_l, a_l)
    if slack < -1e-9:
        assert np.isinf(z) and np.isinf(ref)
        return
    if v_f > v_l:  # really closing at the margin: far beyond any mechanical limit (unsafe)
        assert z > PRM.a_x_d and not ref <= PRM.a_x_d
        return
    assert np.isfinite(z), (slack, v_f, v_l, a_l)
    if v_f * v_f < 2.0 * 1e-12:  # stopping distances below 1e-12 m at any braking >= 1 m/s²: beyond the
        # reference's resolution (it bisects positions to ~1e-9 m), where it answers 0; the closed form gives the
        # exact limit a_l·(v_f/v_l)² of a pair at the margin. Both are safe verdicts: compare those.
        assert (z <= PRM.a_x_d) == (ref <= PRM.a_x_d)
        return
    # The reference bisects on log z down to 1e-9; both are "no braking needed" below that.
    assert z == pytest.approx(ref, rel=1e-6, abs=2e-9)
    if v_l > 1e-6 and a_l > 0.0:  # the slack -> 0+ limit of z_B, up to the 1 nm tolerance
        z0 = a_l * (v_f / v_l) ** 2
        assert z == pytest.approx(z0, abs=z0 * min(2.1e-9 * a_l / v_l**2, 1.0) + 1e-12)


@settings(max_examples=200, deadline=None)
@given(v=st.floats(0.1, 40.0), a_l=st.floats(0.05, 8.0), dv=st.floats(-10.0, 0.0))
def test_min_follow_decel_is_continuous_as_the_slack_goes_to_zero(v, a_l, dv):
    v_f = max(v + dv, 0.0)
    at_zero = _z_both(0.0, v_f, v, a_l)
    for eps in (1e-3, 1e-6, 1e-9, 1e-12):
        # |dz/dslack| = 2 v_f² / (2 slack + v²/a)² <= 2 a² / v² for a pair that is not closing
        tol = 2.0 * (eps + 1e-9) * a_l**2 / v**2 * 1.001 + 1e-12
        assert _z_both(eps, v_f, v, a_l) == pytest.approx(at_zero, abs=tol)


def test_inside_the_margin_beyond_round_off_stays_unsafe():
    assert np.isinf(_z_both(-1e-6, 30.0, 30.0, 1.0))
    assert np.isinf(_z_both(-2e-9, 0.0, 0.0, 1.0))


def test_round_off_closing_speed_at_the_margin_is_not_a_jump():
    """The state the invariant test produced: L1 at the margin, faster than L2 by 4e-15 m/s after a speed match."""
    z = _z_both(0.0, 18.393821213169694, 18.39382121316969, 2.62533472)
    assert z == pytest.approx(2.62533472, rel=1e-9)


def test_braking_at_z_keeps_the_margin_and_less_does_not_time_stepped():
    """Independent of any closed form: exact constant-deceleration positions on a dense grid."""
    t = np.linspace(0.0, 60.0, 600_001)

    def min_gap(z, slack, v_f, v_l, a_l):
        def pos(v, a):
            tt = np.minimum(t, v / a if a > 0 else np.inf)
            return v * tt - 0.5 * a * tt * tt

        return (slack + pos(v_l, a_l) - pos(v_f, z)).min()

    for v_f, v_l, a_l in [(30.0, 30.0, 6.0), (25.0, 30.0, 8.0), (20.0, 30.0, 2.0)]:
        z = _z_both(0.0, v_f, v_l, a_l)
        assert min_gap(z, 0.0, v_f, v_l, a_l) >= -1e-9 * (1 + 1e-5)  # the 1 nm tolerance, grid round-off
        assert min_gap(z * 0.99, 0.0, v_f, v_l, a_l) < -1e-6


@pytest.mark.parametrize("slack", BOUNDARY_SLACKS)
def test_chain_bound_at_the_margin_is_the_ahead_vehicles_bound(slack):
    """L1 exactly at its margin behind L2 at the same speed (where the chain's own worst-case trajectory ends):
    L1's bound is L2's (braking like it suffices), not a_x_d — the jump the adversarial search exploited."""
    p2, v = 40.0, 25.0
    p = [p2 - PRM.p_m - slack, p2, p2 + 30.0]
    res = leader_chain(p, [v, v, v], [0.5, 0.5], PRM)
    assert not res.unsafe
    assert res.l1_decel == pytest.approx(res.decel[1], rel=1e-6)
    nearby = leader_chain([p[0] - 1e-6, p[1], p[2]], [v, v, v], [0.5, 0.5], PRM)
    assert nearby.l1_decel == pytest.approx(res.l1_decel, rel=1e-5)


# --- L(N+1) profiles, exact in-period switching -------------------------------------------------------------------


def test_switched_fleet_matches_dense_integration():
    """Against an independent per-vehicle integration: 1000 sub-steps, the switch instant inserted as a node,
    each sub-step exact at constant acceleration with stopping."""
    rng = np.random.default_rng(3)
    n = 120
    dt = PRM.dt
    x = rng.uniform(-50, 50, n)
    v = rng.choice([0.0, 0.3, 5.0, 30.0], n)
    a1, a2 = rng.uniform(-8, 2, n), rng.uniform(-8, 2, n)
    t_sw = rng.uniform(0.0, dt, n)
    t_sw[:10] = dt  # no switch
    fleet = Fleet.switched(x, v, a1, t_sw, a2, dt)
    m = fleet.motion(...)
    max_err = 0.0
    for i in range(n):
        nodes = np.union1d(np.linspace(0.0, dt, 1001), [t_sw[i]])
        xi, vi = x[i], v[i]
        for t0, t1 in itertools.pairwise(nodes):
            a = a1[i] if t0 < t_sw[i] else a2[i]
            h = t1 - t0
            if a < 0 and vi + a * h < 0:
                xi, vi = xi + vi * vi / (-2 * a), 0.0
            else:
                xi, vi = xi + vi * h + 0.5 * a * h * h, vi + a * h
            got_x, got_v = m.at(np.full((n, 1), t1))
            max_err = max(max_err, abs(got_x[i, 0] - xi), abs(got_v[i, 0] - vi))
    assert max_err < 1e-9
    assert np.allclose(fleet.x_end, m.x[:, -1]) and np.allclose(fleet.v_end, m.v[:, -1])


def test_last_profile_validation_names_the_problem():
    batch = paper_scenarios("CV_all", 1, 5.0, 2, np.random.default_rng(0))
    with pytest.raises(ValueError, match="at least one period"):
        with_last_profile(batch, [[0.0, 1.0, 1.05]] * 2, [[0.0, -8.0, 0.0]] * 2)
    with pytest.raises(ValueError, match=r"a_o_d=-8\.0"):  # L(N+1) brakes up to the others' maximum (a_x_d unless set)
        with_last_profile(batch, [[0.0, 1.0]] * 2, [[0.0, -9.0]] * 2)
    harder = Params(a_o_d=9.5)
    assert with_last_profile(batch, [[0.0, 1.0]] * 2, [[0.0, -9.5]] * 2, harder).last_profile_a.min() == -9.5
    with pytest.raises(ValueError, match=r"a_o_d=-9\.5"):
        with_last_profile(batch, [[0.0, 1.0]] * 2, [[0.0, -9.6]] * 2, harder)
    with pytest.raises(ValueError, match=r"\[:, 0\] must be 0"):
        with_last_profile(batch, [[0.5, 1.0]] * 2, [[0.0, -8.0]] * 2)


def _random_profiles(rng, n, horizon=10.0, segments=6):
    gaps = rng.choice([0.1, 0.1 + 1e-12, 0.137, 0.5, 1.0, 2.0], size=(n, segments - 1))
    # Events aligned with period boundaries, just off them, and inside periods.
    t = np.concatenate([np.zeros((n, 1)), np.cumsum(gaps + rng.choice([0.0, 0.05, 0.0731], size=gaps.shape), 1)], 1)
    t = np.minimum(t, horizon)
    a = rng.choice([-PRM.a_x_d, -6.0, -2.0, -0.5, 0.0, 1.0, PRM.a_x_a], size=(n, segments))
    return t, a


class _RandomTasks:
    """Leader tasks anywhere inside (and beyond: the simulator clips) the promises, keyed by scenario id."""

    def __init__(self, seed):
        self.seed = seed

    def __call__(self, view, prm):
        rng = np.random.default_rng([self.seed, round(view.t * 10)])
        return rng.uniform(-3.0, 3.0, size=view.x.shape)


@pytest.mark.parametrize("n_leaders", [0, 1, 3, 6])
def test_consistency_invariant_under_profiles_and_tasks(n_leaders):
    """No leader violates its margin, and no leader ever brakes harder than the smallest bound the chain gave it
    at any earlier time (what the ego's held plans rely on)."""
    rng = np.random.default_rng(n_leaders)
    n = 300
    batch = paper_scenarios("CV_all", n_leaders, 8.0, n, rng)
    # Tight chains: leaders at random slacks just above their margin, at differing speeds.
    k = batch.x.shape[1]
    slack = rng.choice([0.0, 1e-12, 0.3, 3.0, 10.0], size=(n, k))
    x = batch.x.copy()
    v = np.clip(batch.v + rng.choice([0.0, 0.0, -0.5, 2.0], size=(n, k)), 0.0, None)
    for j in range(k - 2, 0, -1):
        x[:, j] = x[:, j + 1] - PRM.p_m - slack[:, j]
        v[:, j] = np.minimum(v[:, j], v[:, j + 1])  # not closing initially: the chain is safe at t = 0
    batch = dataclasses.replace(batch, x=x, v=v)
    t, a = _random_profiles(rng, n)
    batch = with_last_profile(batch, t, a)
    cfg = SimConfig(horizon_s=6.0)
    sim = ClosedLoop(batch, 0, PRM, cfg, _Expert(), TrafficHooks(leader_task=_RandomTasks(n_leaders)))
    s = sim.initial_state()
    running = np.full((n, k), np.inf)
    worst_excess = -np.inf
    for _ in range(round(cfg.horizon_s / PRM.dt)):
        bounds, unsafe = sim.chain(s)
        assert not unsafe.any()
        running = np.minimum(running, bounds)
        s, _, _ = sim.step(s)
        connected = (np.arange(k)[None, :] >= 1) & (np.arange(k)[None, :] <= batch.n_connected[:, None])
        excess = np.where(connected, -s.acc - running, -np.inf)
        worst_excess = max(worst_excess, float(excess.max()))
    assert worst_excess <= 1e-9, worst_excess
    assert not s.leader_violated.any() and not s.leader_collided.any()
    assert not s.breach.any.any()


class _Expert:
    def __call__(self, obs, prm):
        from safelane.planners.base import ExpertPlanner

        return ExpertPlanner()(obs, prm)


# --- invalid proposals ----------------------------------------------------------------------------------------------


class _Broken:
    """Every ``every``-th period returns ``value`` for a_x on half the rows."""

    def __init__(self, value, every=3):
        self.value, self.every = value, every

    def __call__(self, obs, prm):
        from safelane.planners.base import ExpertPlanner

        a_x, a_y = ExpertPlanner()(obs, prm)
        if round(obs.t / prm.dt) % self.every == 0:
            a_x = a_x.copy()
            a_x[::2] = self.value
        return a_x, a_y


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 50.0, -9.0])
def test_invalid_proposals_are_counted_and_never_reach_the_state(value):
    res = simulate("CV_all", n_leaders=2, decel=5.0, samples=40, seed=1, nominal=_Broken(value))
    tb = res.table
    assert (tb.n_invalid_proposals[::2] > 0).all() and (tb.n_invalid_proposals[1::2] == 0).all()
    assert not tb.collision.any() and not tb.safety_violation.any()
    assert np.isfinite(tb.min_gap_leader_m.fillna(0)).all()


@pytest.mark.parametrize(
    ("answer", "error", "match"),
    [
        (lambda n: (np.zeros(n + 1), np.zeros(n)), ValueError, r"a_x of shape \(\d+,\); expected"),
        (lambda n: (np.zeros((n, 1)), np.zeros(n)), ValueError, "shape"),
        (lambda n: (np.array(["a"] * n), np.zeros(n)), TypeError, "numbers"),
        (lambda n: (np.zeros(n, bool), np.zeros(n)), TypeError, "numbers"),
        (lambda n: np.zeros(n), TypeError, "pair"),
        (lambda n: None, TypeError, "pair"),
    ],
)
def test_wrong_shapes_and_types_are_errors_naming_the_planner(answer, error, match):
    def weird_planner(obs, prm):
        return answer(len(obs.p_x))

    with pytest.raises(error, match=match) as info:
        simulate("CV_all", n_leaders=1, decel=5.0, samples=5, seed=0, nominal=weird_planner)
    assert "weird_planner" in str(info.value)


def test_non_finite_state_is_caught_not_reported_as_no_collision():
    from safelane.sim.step import _check_finite

    batch = paper_scenarios("CV_all", 1, 5.0, 3, np.random.default_rng(0))
    sim = ClosedLoop(batch, 0, PRM, SimConfig(), _Expert())
    s = sim.initial_state()
    ex = s.ego[0].copy()
    ex[1] = np.nan
    with pytest.raises(FloatingPointError, match=r"scenario\(s\) \[1\]"):
        _check_finite(dataclasses.replace(s, ego=(ex, *s.ego[1:])), batch)


# --- the assumption monitor -----------------------------------------------------------------------------------------


def test_monitor_silent_inside_the_assumptions_and_records_promise_violations():
    inside = simulate("CV_all", n_leaders=3, decel=6.0, samples=300, seed=0, config=SimConfig(assessment="truth"))
    assert not inside.table.assumption_breach.any()
    outside = simulate("CV_all", n_leaders=3, decel=6.0, samples=300, seed=0, p_v=0.3)
    tb = outside.table
    assert tb.breach_leader_bound.mean() > 0.5
    assert (tb.breach_time_s[tb.assumption_breach] > 0).all()
    assert tb.breach_time_s[~tb.assumption_breach].isna().all()


def test_monitor_flags_an_aggressive_follower_believed_collaborative():
    """F's true type aggressive but the variant told it is collaborative (F connected but not yielding)."""
    rng = np.random.default_rng(0)
    batch = paper_scenarios("CV_follow", 1, 2.0, 200, rng)
    batch = dataclasses.replace(batch, follower_aggressive=np.ones(200, bool))  # connected, yet aggressive
    on = simulate_batch(batch, 0, config=SimConfig(monitor=True)).table
    off = simulate_batch(batch, 0, config=SimConfig(monitor=False)).table
    assert on.breach_follower.any() and off.breach_follower.any()
    assert on.collision.sum() <= off.collision.sum()


# --- V2X emulation in the loop ----------------------------------------------------------------------------------


def test_received_chain_equals_leader_arrays_on_random_message_sets():
    """The vectorized staleness fallback against the per-message reference implementation of safelane.v2x."""
    from safelane.v2x import SensedVehicle, V2XMessage, leader_arrays, received_chain

    rng = np.random.default_rng(5)
    n, k, now = 200, 5, 10.0
    t = now - rng.choice([0.0, 0.1, 0.2, 0.3, 0.3 + 1e-6, 0.5, 1.0], size=(n, k))
    p = np.cumsum(rng.uniform(8.0, 25.0, size=(n, k)), 1)
    v = rng.uniform(0.0, 30.0, size=(n, k))
    a = rng.uniform(-6.0, 1.0, size=(n, k))
    connected = rng.uniform(size=(n, k)) < 0.8
    connected[:, -1] = rng.uniform(size=n) < 0.5
    got_p, got_v, got_n, _ = received_chain(t, p, v, a, connected, now, PRM)
    for i in range(n):
        vehicles = [
            V2XMessage(vehicle_id=f"v{j}", timestamp_s=t[i, j], position_m=p[i, j], speed_mps=v[i, j],
                       accel_mps2=a[i, j], promise_decel=0.5, promise_accel=0.5, human_driven=False)
            if connected[i, j]
            else SensedVehicle(vehicle_id=f"v{j}", timestamp_s=t[i, j], position_m=p[i, j], speed_mps=v[i, j])
            for j in range(k)
        ]  # fmt: skip
        ref = leader_arrays(vehicles, now, PRM)
        assert got_n[i] == ref.n_connected
        m = ref.n_connected + 1
        np.testing.assert_allclose(got_p[i, :m], ref.p, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got_v[i, :m], ref.v, rtol=0, atol=1e-12)
        assert (got_p[i, m:] > ref.p[-1] + 1e5).all()


def test_v2x_emulation_off_is_perfect_v2x_and_on_is_conservative():
    base = simulate("CV_all", n_leaders=3, decel=4.0, samples=200, seed=2).table
    same = simulate(
        "CV_all", n_leaders=3, decel=4.0, samples=200, seed=2, config=SimConfig(v2x_max_age_s=0.0)
    ).table  # no loss, no latency: every message fresh
    assert base.equals(same)
    lossy = simulate("CV_all", n_leaders=3, decel=4.0, samples=200, seed=2, config=SimConfig(v2x_loss=0.5)).table
    assert lossy.breach_stale_v2x.mean() > 0.5
    assert lossy.success.mean() <= base.success.mean()
    assert not lossy.collision.any() and not lossy.safety_violation.any()
    late = SimConfig(v2x_latency_periods=2, v2x_max_age_s=0.3)
    table = simulate("CV_all", n_leaders=3, decel=4.0, samples=200, seed=2, config=late).table
    assert not table.breach_stale_v2x.any()  # 0.2 s old messages are still fresh


def test_leader_closed_form_is_exact_when_its_own_bound_is_at_least_the_one_ahead():
    """leader_accels skips the exact check where own >= d: there the closed form must be safe and maximal."""
    from safelane.safety.responsible import responsible_bound, responsible_ok

    rng = np.random.default_rng(11)
    n = 100_000
    slack = rng.choice([0.0, 1e-9, 0.5, 3.0, 12.0], n) + rng.uniform(0, 2, n)
    v_f, v_l = rng.uniform(0, 35, n), rng.uniform(0, 35, n)
    d = rng.uniform(0, PRM.a_x_d, n)
    own = d + rng.uniform(0, PRM.a_x_d, n) * (PRM.a_x_d - d) / PRM.a_x_d  # own in [d, a_x_d]
    a = responsible_bound(slack, v_f, v_l, d, PRM, brake=own) - 1e-9
    inside = a >= -own
    ok = responsible_ok(a, slack, v_f, v_l, d, PRM, brake=own, tol=1e-9)
    assert ok[inside].all()
    larger = responsible_ok(a + 1e-6, slack, v_f, v_l, d, PRM, brake=own)
    assert not larger[inside & (a + 1e-6 < PRM.a_x_a)].any()
