"""The shield's decision, ``shield.decide.check_candidate``, against an independent brute-force reference.

The reference (:func:`ref_check_candidate`) imports nothing from the library's decision or closed forms. It
time-steps the period on a fine grid: the ego under the proposal ``(a_x, a_y)``; L1 and F under *sampled*
admissible motions — each vehicle's worst case (L1 braking at its worst-case deceleration, F at ``+a_x_a`` if
aggressive, braking at ``a_x_d`` if collaborative) and random piecewise-constant motions that never leave it
(L1 never brakes harder, F never accelerates more); while the ego is ever outside ``y_safe`` during the period,
both gaps must stay ``>= p_m`` at every sampled instant. Then, from the predicted state at the end of the period,
the evasion over its horizon is decided by ``tests/reference.py`` (bisection on simulated motions), or — for a
step that crosses the lane boundary — the completion guard by simulating both followers braking at ``a_x_d``.

Agreement is asserted up to a band: the reference run with margins ``p_m + EPS`` must imply the library's
acceptance, and the library's acceptance must imply the reference with ``p_m − EPS``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import scenarios
from reference import follow_gap_margin, ref_evasion_exists
from safelane import Params
from safelane.safety import plan_evasion
from safelane.safety.lateral import LATERAL_TOL_M
from safelane.safety.longitudinal import FEASIBILITY_TOL_M
from safelane.shield.decide import check_candidate, commit_guard, hesitate_lateral, plan_motion
from safelane.shield.policies import COMPLETION_RULES

PRM = Params()
#: Agreement band [m]: far above the library's tolerances (1 nm) and the reference's grid error (~1e-6 m).
EPS = 1e-4
#: Time nodes over one period, and random admissible motions per vehicle (besides its worst case).
N_T, N_MOTIONS = 241, 6


def _roll(x0, v0, acc, h):
    """Exact stepping with stops: ``acc`` ``(..., S)`` constant on each of ``S`` substeps of length ``h``;
    returns positions ``(..., S + 1)``."""
    x, v = (np.broadcast_to(z, acc.shape[:-1]) for z in (x0, v0))
    xs = [x]
    for k in range(acc.shape[-1]):
        a = acc[..., k]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_rest = np.where(a < 0.0, v / -a, np.inf)
        hh = np.minimum(h, t_rest)
        x = x + v * hh + 0.5 * a * hh * hh
        v = np.maximum(v + a * hh, 0.0)
        xs.append(x)
    return np.stack(xs, -1)


def _motions(x0, v0, worst, other, rng):
    """Positions ``(B, 1 + N_MOTIONS, N_T)``: the worst-case motion (constant ``worst``) and random piecewise-
    constant motions with accelerations between ``other`` and ``worst`` (4 pieces each)."""
    b = x0.shape[0]
    pieces = rng.uniform(0.0, 1.0, (b, N_MOTIONS, 4))
    acc_pieces = other[:, None, None] + pieces * (worst - other)[:, None, None]
    acc = np.repeat(acc_pieces, -(-(N_T - 1) // 4), axis=-1)[..., : N_T - 1]
    acc = np.concatenate([np.broadcast_to(worst[:, None, None], (b, 1, N_T - 1)), acc], axis=1)
    return _roll(x0[:, None], v0[:, None], acc, PRM.dt / (N_T - 1))


def ref_check_candidate(s: dict, margin_shift: float, rng, rule: str = "commit_guard") -> np.ndarray:
    """The brute-force verdict on the states ``s`` (1-D arrays), with every margin ``p_m + margin_shift`` and the
    conflict zone entered ``margin_shift`` beyond ``y_safe`` (so a positive shift is strictly more cautious).
    ``rule``: the completion rule for a step crossing the lane boundary — ``commit_guard`` (both followers can
    keep ``p_m`` braking at ``a_x_d``) or ``paper_evasion`` (the evasion check decides, as on every step)."""
    p_m = PRM.p_m + margin_shift
    b = s["ego_x"].shape[0]
    t = np.linspace(0.0, PRM.dt, N_T)
    ego = _roll(s["ego_x"], s["ego_vx"], np.repeat(s["a_x"][:, None], N_T - 1, 1), PRM.dt / (N_T - 1))
    ego_y = s["ego_y"][:, None] + s["ego_vy"][:, None] * t + 0.5 * s["a_y"][:, None] * t * t
    l1 = _motions(s["l1_x"], s["l1_v"], -s["l1_decel"], np.full(b, PRM.a_x_a), rng)  # never brakes harder
    a_f = np.where(s["f_aggressive"], PRM.a_x_a, -PRM.a_x_d)
    f = _motions(s["f_x"], s["f_v"], a_f, np.full(b, -PRM.a_x_d - 2.0), rng)  # never accelerates more
    in_zone = (ego_y > PRM.y_safe - margin_shift).any(1)
    gap_l = (l1 - ego[:, None, :]).min((1, 2))
    gap_f = (ego[:, None, :] - f).min((1, 2))
    period_ok = ~in_zone | ((gap_l >= p_m) & (gap_f >= p_m))

    # The predicted state: the worst-case motions' ends (index 0), the ego's own end.
    ex, lx, fx = ego[:, -1], l1[:, 0, -1], f[:, 0, -1]
    evx = np.maximum(s["ego_vx"] + s["a_x"] * PRM.dt, 0.0)
    lv = np.maximum(s["l1_v"] - s["l1_decel"] * PRM.dt, 0.0)
    fv = np.maximum(s["f_v"] + a_f * PRM.dt, 0.0)
    ey = ego_y[:, -1]
    evy = s["ego_vy"] + s["a_y"] * PRM.dt
    evasion = ref_evasion_exists(ex, ey, evx, evy, lx, lv, s["l1_decel"], fx, fv, s["f_aggressive"], PRM, p_m, p_m)
    keep_l = follow_gap_margin(np.full(b, PRM.a_x_d), ex, evx, lx, lv, s["l1_decel"], p_m)[0] >= 0.0
    keep_f = follow_gap_margin(np.full(b, PRM.a_x_d), fx, fv, ex, evx, np.full(b, PRM.a_x_d), p_m)[0] >= 0.0
    completing = ey >= PRM.y_boundary
    crossing_ok = keep_l & keep_f if rule == "commit_guard" else evasion.exists
    return period_ok & np.where(completing, crossing_ok, evasion.exists)


def predicted_state(s: dict) -> tuple:
    """The state at the end of the period under the proposal and the worst case (plain kinematics, stopping)."""

    def step(x, v, a):
        t = np.where(a < 0, np.minimum(v / np.where(a < 0, -a, 1.0), PRM.dt), PRM.dt)
        return x + v * t + 0.5 * a * t * t, np.maximum(v + a * t, 0.0)

    ex, evx = step(s["ego_x"], s["ego_vx"], s["a_x"])
    lx, lv = step(s["l1_x"], s["l1_v"], -s["l1_decel"])
    fx, fv = step(s["f_x"], s["f_v"], np.where(s["f_aggressive"], PRM.a_x_a, -PRM.a_x_d))
    ey = s["ego_y"] + s["ego_vy"] * PRM.dt + 0.5 * s["a_y"] * PRM.dt**2
    evy = s["ego_vy"] + s["a_y"] * PRM.dt
    return ex, ey, evx, evy, lx, lv, s["l1_decel"], fx, fv, s["f_aggressive"]


def _states(n: int, rng) -> dict:
    """States near the decision's boundaries: gaps a few centimetres around ``p_m`` for half of the rows, the
    ego on both sides of ``y_safe`` and of the lane boundary, F faster or slower than the ego."""
    u = rng.uniform
    ego_vx = u(2.0, 30.0, n)
    near = u(0, 1, n) < 0.5
    slack_l = np.where(near, u(-0.03, 0.06, n), u(0.0, 40.0, n))
    slack_f = np.where(u(0, 1, n) < 0.5, u(-0.03, 0.06, n), u(0.0, 40.0, n))
    s = {
        "ego_x": u(-50.0, 50.0, n),
        "ego_y": u(-0.3, 2.2, n),
        "ego_vx": ego_vx,
        "ego_vy": u(-1.2, 1.2, n),
        "a_x": np.where(u(0, 1, n) < 0.2, rng.choice([-PRM.a_x_d, 0.0, PRM.a_x_a], n), u(-PRM.a_x_d, PRM.a_x_a, n)),
        "a_y": np.where(u(0, 1, n) < 0.2, rng.choice([-PRM.a_y_m, 0.0, PRM.a_y_m], n), u(-PRM.a_y_m, PRM.a_y_m, n)),
        "l1_v": np.maximum(ego_vx + u(-2.0, 2.0, n), 0.0),
        "l1_decel": np.where(u(0, 1, n) < 0.2, PRM.a_x_d, u(0.0, PRM.a_x_d, n)),
        "f_v": np.maximum(ego_vx + u(-2.0, 2.0, n), 0.0),
        "f_aggressive": u(0, 1, n) < 0.5,
    }
    s["l1_x"] = s["ego_x"] + PRM.p_m + slack_l
    s["f_x"] = s["ego_x"] - PRM.p_m - slack_f
    return s


def _follower_dip_states(n: int, rng) -> dict:
    """A collaborative F slightly faster than an accelerating ego, starting just outside ``p_m``: the gap closes
    and reopens inside the period, so only the within-period check can see it dip below ``p_m``."""
    s = _states(n, rng)
    s["ego_y"] = rng.uniform(1.0, 1.5, n)
    s["ego_vy"] = rng.uniform(-0.2, 0.3, n)
    s["a_x"] = rng.uniform(0.0, PRM.a_x_a, n)
    s["f_aggressive"] = np.zeros(n, bool)
    s["f_v"] = s["ego_vx"] + rng.uniform(0.1, 0.9, n)
    s["f_x"] = s["ego_x"] - PRM.p_m - rng.uniform(-0.005, 0.03, n)
    s["l1_x"] = s["ego_x"] + PRM.p_m + rng.uniform(20.0, 40.0, n)
    return s


def _leader_dip_states(n: int, rng) -> dict:
    """The ego braking harder than L1's worst case while still faster than L1, just outside ``p_m`` behind it."""
    s = _states(n, rng)
    s["ego_y"] = rng.uniform(1.0, 1.5, n)
    s["ego_vy"] = rng.uniform(-0.2, 0.3, n)
    s["l1_decel"] = rng.uniform(0.0, 4.0, n)
    s["a_x"] = -s["l1_decel"] - rng.uniform(2.0, PRM.a_x_d - 4.0, n)
    s["l1_v"] = np.maximum(s["ego_vx"] - rng.uniform(0.05, 0.4, n), 0.0)
    s["l1_x"] = s["ego_x"] + PRM.p_m + rng.uniform(-0.005, 0.02, n)
    s["f_x"] = s["ego_x"] - PRM.p_m - rng.uniform(20.0, 40.0, n)
    return s


ORDER = ("ego_x", "ego_y", "ego_vx", "ego_vy", "a_x", "a_y", "l1_x", "l1_v", "l1_decel", "f_x", "f_v", "f_aggressive")


def _library(s: dict):
    return check_candidate(*(s[k] for k in ORDER), PRM)


@pytest.mark.parametrize(
    ("family", "n", "seed"),
    [("boundary", 3000, 0), ("follower_dip", 600, 1), ("leader_dip", 600, 2)],
)
def test_decision_matches_brute_force_reference(family, n, seed):
    rng = np.random.default_rng(seed)
    s = {"boundary": _states, "follower_dip": _follower_dip_states, "leader_dip": _leader_dip_states}[family](n, rng)
    verdict = _library(s)
    strict = ref_check_candidate(s, EPS, np.random.default_rng(seed + 100))
    loose = ref_check_candidate(s, -EPS, np.random.default_rng(seed + 100))
    assert not (strict & ~verdict.ok).any(), np.flatnonzero(strict & ~verdict.ok)[:10]
    assert not (verdict.ok & ~loose).any(), np.flatnonzero(verdict.ok & ~loose)[:10]
    # Not vacuous: both verdicts occur clearly (outside the band).
    assert strict.sum() > n // 20 and (~loose).sum() > n // 20
    # The plans cover exactly the accepted rows, and each is the evasion plan from the predicted state.
    rows = np.sort(np.concatenate([r for r, _ in verdict.plans]))
    assert np.array_equal(rows, np.flatnonzero(verdict.ok))
    assert np.array_equal(verdict.completing, s["ego_y"] + s["ego_vy"] * PRM.dt + 0.5 * s["a_y"] * PRM.dt**2 >= 1.75)
    predicted = predicted_state(s)
    for r, plan in verdict.plans:
        want = plan_evasion(*(a[r] for a in predicted), PRM)
        assert plan.params == PRM and np.array_equal(plan.feasible, want.feasible)
        for field in ("t_y_f", "t_x1", "t_brake_end", "t_y_end"):
            np.testing.assert_allclose(getattr(plan, field), getattr(want, field), rtol=1e-9, atol=1e-9)


def test_paper_completion_rule_decides_the_crossing_step_by_the_evasion_check():
    rng = np.random.default_rng(5)
    s = _states(3000, rng)
    s["ego_y"], s["ego_vy"] = rng.uniform(1.5, 1.9, 3000), rng.uniform(0.0, 1.2, 3000)  # mostly crossing steps
    verdict = check_candidate(*(s[k] for k in ORDER), PRM, completion=COMPLETION_RULES["paper_evasion"])
    strict = ref_check_candidate(s, EPS, np.random.default_rng(6), rule="paper_evasion")
    loose = ref_check_candidate(s, -EPS, np.random.default_rng(6), rule="paper_evasion")
    assert not (strict & ~verdict.ok).any() and not (verdict.ok & ~loose).any()
    # The two rules clearly differ on crossing steps, both ways.
    guard_strict = ref_check_candidate(s, EPS, np.random.default_rng(6))
    guard_loose = ref_check_candidate(s, -EPS, np.random.default_rng(6))
    assert (verdict.completing & strict & ~guard_loose).sum() > 10
    assert (verdict.completing & guard_strict & ~loose).sum() > 10


def test_body_across_rule_checks_every_step_until_the_whole_car_is_across():
    """``paper_body_across``: the evasion check decides every step, the crossing of the centre line included (the
    brute-force reference with the paper's rule), and a step completes only at ``y_boundary + w_v / 2``."""
    rng = np.random.default_rng(11)
    s = _states(3000, rng)
    s["ego_y"], s["ego_vy"] = rng.uniform(1.5, 2.9, 3000), rng.uniform(0.0, 1.2, 3000)  # centre and body crossings
    rule = COMPLETION_RULES["paper_body_across"]
    verdict = check_candidate(*(s[k] for k in ORDER), PRM, completion=rule)
    strict = ref_check_candidate(s, EPS, np.random.default_rng(12), rule="paper_evasion")
    loose = ref_check_candidate(s, -EPS, np.random.default_rng(12), rule="paper_evasion")
    assert not (strict & ~verdict.ok).any() and not (verdict.ok & ~loose).any()
    y_end = s["ego_y"] + s["ego_vy"] * PRM.dt + 0.5 * s["a_y"] * PRM.dt**2
    level = PRM.y_boundary + 0.5 * PRM.vehicle_width
    assert rule.level(PRM) == level == 1.75 + 0.9
    assert np.array_equal(verdict.completing, y_end >= level)
    centre_only = (y_end >= PRM.y_boundary) & (y_end < level)
    assert centre_only.sum() > 100 and not verdict.completing[centre_only].any()


def test_decision_raises_no_floating_point_warnings():
    # Divisions by zero and infinities inside are expected and handled; none may reach the caller as a warning.
    s = _states(500, np.random.default_rng(3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _library(s)
        _library(_follower_dip_states(200, np.random.default_rng(4)))


def _dip_state(**overrides) -> dict:
    """One row: the ego at ``y = 1.2`` (in the conflict zone, not completing), 20 m/s, F and L1 far unless
    overridden."""
    s = dict(ego_x=0.0, ego_y=1.2, ego_vx=20.0, ego_vy=0.0, a_x=0.0, a_y=0.0, l1_x=60.0, l1_v=20.0, l1_decel=2.0,
             f_x=-60.0, f_v=20.0, f_aggressive=False)  # fmt: skip
    s.update(overrides)
    return {k: np.atleast_1d(np.asarray(v, dtype=bool if k == "f_aggressive" else float)) for k, v in s.items()}


def follower_gap_dips_inside_the_period(start_slack_m: float) -> dict:
    """F collaborative 0.5 m/s faster than the ego, which accelerates at ``a_x_a``: relative acceleration
    ``a_x_a + a_x_d = 10.5``, so the gap is smallest at ``t = 0.5/10.5 ≈ 0.048 s``, 1.19 cm below its start, and
    back to 0.25 cm above its start at the period's end."""
    return _dip_state(a_x=PRM.a_x_a, f_x=-(PRM.p_m + start_slack_m), f_v=20.5)


def leader_gap_dips_inside_the_period(start_slack_m: float) -> dict:
    """The ego braking at ``a_x_d`` 0.3 m/s faster than L1 braking at 2: relative deceleration 6, the gap is
    smallest at ``t = 0.05 s``, 0.75 cm below its start, and back to its start at the period's end."""
    return _dip_state(a_x=-PRM.a_x_d, l1_x=PRM.p_m + start_slack_m, l1_v=19.7, l1_decel=2.0)


def _crossing(**overrides) -> dict:
    """A step across the lane boundary (the ego's centre from 1.74 m past 1.75 m), L1 and F 30 m away."""
    return _dip_state(**{"ego_y": 1.74, "ego_vy": 0.5, "l1_x": 30.0, "f_x": -30.0, **overrides})


def test_period_check_rejects_a_follower_gap_dipping_below_p_m_inside_the_period():
    # Kills the mutant that drops `gap_f` from `period_ok`: the end-of-period state is fine (an evasion exists from
    # it, F 0.75 cm outside p_m), only the gap inside the period is 0.69 cm short.
    dips = follower_gap_dips_inside_the_period(0.005)
    assert not _library(dips).ok[0]
    assert not ref_check_candidate(dips, 0.0, np.random.default_rng(0))[0]
    clear = follower_gap_dips_inside_the_period(0.02)  # the same motion with 2 cm to spare: accepted
    assert _library(clear).ok[0] and ref_check_candidate(clear, 0.0, np.random.default_rng(0))[0]


def test_period_check_rejects_a_leader_gap_dipping_below_p_m_inside_the_period():
    dips = leader_gap_dips_inside_the_period(0.004)
    assert not _library(dips).ok[0]
    assert not ref_check_candidate(dips, 0.0, np.random.default_rng(0))[0]
    clear = leader_gap_dips_inside_the_period(0.02)
    assert _library(clear).ok[0] and ref_check_candidate(clear, 0.0, np.random.default_rng(0))[0]


def test_period_check_tolerance_is_inclusive():
    # A gap exactly FEASIBILITY_TOL_M (1 nm) inside p_m counts as kept, one ulp further does not. Exact only where
    # positions are of the tolerance's magnitude: a nanometre-long car and p_m = 2^-29 m (all differences exact).
    tiny = Params(vehicle_length=1e-9, p_m=2.0**-29, p_m_human=2.0**-29)
    at_rest = dict(ego_vx=0.0, l1_v=0.0, l1_decel=0.0, f_v=0.0, l1_x=30.0, f_x=-30.0)
    lead, follow = tiny.p_m - FEASIBILITY_TOL_M, -(tiny.p_m - FEASIBILITY_TOL_M)
    assert lead - tiny.p_m == -FEASIBILITY_TOL_M and 0.0 - follow - tiny.p_m == -FEASIBILITY_TOL_M
    for key, at_tol, beyond in (("l1_x", lead, np.nextafter(lead, -1)), ("f_x", follow, np.nextafter(follow, 1))):
        for value, accepted in ((at_tol, True), (beyond, False)):
            state = _dip_state(**{**at_rest, key: value})
            assert check_candidate(*(state[k] for k in ORDER), tiny).ok[0] == accepted, (key, value)


def test_conflict_zone_starts_strictly_beyond_y_safe_plus_tolerance():
    # The dipping follower gap matters only if the ego is ever beyond y_safe + LATERAL_TOL_M in the period.
    edge = PRM.y_safe + LATERAL_TOL_M
    for y, accepted in ((PRM.y_safe, True), (edge, True), (np.nextafter(edge, 9.0), False)):
        state = {**follower_gap_dips_inside_the_period(0.005), "ego_y": np.array([y])}
        assert _library(state).ok[0] == accepted, y


def test_period_check_applies_only_in_the_conflict_zone():
    # The same dipping follower gap with the ego wholly in its own lane all period: no conflict, accepted.
    in_lane = {**follower_gap_dips_inside_the_period(0.005), "ego_y": np.array([0.0])}
    assert _library(in_lane).ok[0]


def test_completion_guard_needs_both_followers_able_to_keep_p_m():
    # A step across the lane boundary: accepted with room ahead and behind, refused with L1 (or F) too close to
    # brake for at a_x_d.
    ok = _library(_crossing())
    assert ok.completing[0] and ok.ok[0]
    on_the_boundary = _library(_crossing(ego_y=PRM.y_boundary, ego_vy=0.0))  # reaching it counts as crossing
    assert on_the_boundary.completing[0] and on_the_boundary.ok[0]
    for close in ({"l1_x": PRM.p_m + 0.5, "l1_v": 10.0}, {"f_x": -PRM.p_m - 0.5, "f_v": 30.0}):
        verdict = _library(_crossing(**close))
        assert verdict.completing[0] and not verdict.ok[0], close
    # The guard itself at the brink: the ego at 20 m/s needs 25 m to stop at a_x_d behind a stopped L1; F at
    # 30 m/s needs 56.25 m behind a stopped ego.
    z, far = np.array([0.0]), np.array([1e3])
    for slack, expected in ((-1e-3, False), (0.0, True), (1e-3, True)):  # at 0: exactly a_x_d, still enough
        lx = PRM.p_m + 25.0 + slack
        assert commit_guard(z, np.array([20.0]), np.array([lx]), z, z, -far, z, PRM)[0] == expected
        fx = -(PRM.p_m + 56.25 + slack)
        assert commit_guard(z, z, far, z, z, np.array([fx]), np.array([30.0]), PRM)[0] == expected


@pytest.mark.parametrize(
    ("ego_vy", "expected"),
    [(0.05, -0.5), (-0.05, 0.5), (0.0, 0.0), (0.5, -PRM.a_y_m), (-0.5, PRM.a_y_m)],
)
def test_hesitate_brings_the_lateral_speed_to_zero_as_far_as_a_y_m_allows(ego_vy, expected):
    assert float(hesitate_lateral(ego_vy, PRM)) == pytest.approx(expected, abs=1e-12)


def _plans_and_ages():
    """Plans of the named scenarios whose longitudinal plan switches (accelerate → brake → follow L1 to rest, L1
    never braking, a fast lateral return; a slow L1 never braking, one stopping at 1 s at 0.5 m/s²), each with
    periods starting just before each of its switch times and one around 1 s, on a ``(n_scenarios, n_ages)``
    batch."""
    states = [scenarios.follow_l1_to_stop(), scenarios.still_braking_at_horizon(), scenarios.follow_moving_l1(),
              scenarios.past_lane_boundary_returning_fast(), scenarios.ego_stops_before_horizon(),
              {**scenarios.open_gap_collaborative_follower(), "l1_decel": 0.0},
              {**scenarios.open_gap_collaborative_follower(), "l1_v": 1.0, "l1_decel": 0.0},
              {**scenarios.open_gap_collaborative_follower(), "l1_v": 0.5, "l1_decel": 0.5}]  # fmt: skip
    cols = {k: np.array([s[k] for s in states]) for k in states[0]}
    plan = plan_evasion(**cols, params=PRM)
    l1_stop = np.where(cols["l1_decel"] > 0, cols["l1_v"] / np.maximum(cols["l1_decel"], 1e-300), np.inf)
    switches = np.stack([plan.t_x1, plan.t_brake_end, l1_stop, plan.t_y_f, plan.t_y_switch, plan.t_y_end], -1)
    ages = np.clip(np.nan_to_num(switches, posinf=0.0) - 0.04, 0.0, None)  # each switch 0.04 s into a period
    ages = np.concatenate([ages, np.full((len(states), 1), 0.96)], -1)  # and a period around t = 1 s
    batch = plan.take((slice(None), None))  # (n, 1) against ages (n, 7)
    return plan, batch, np.broadcast_to(ages, ages.shape).copy(), l1_stop


def test_plan_motion_knots_are_the_periods_ends_and_every_switch_inside_it():
    plan, batch, ages, l1_stop = _plans_and_ages()
    dt = PRM.dt
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # L1 never braking: no division by zero on the way to "never stops"
        knots, *_ = plan_motion(batch, ages, dt)
    assert knots.shape == (*ages.shape, 8)
    assert (np.diff(knots, axis=-1) >= 0).all() and (knots[..., 0] == 0).all() and (knots[..., -1] == dt).all()
    switches = [plan.t_x1, plan.t_brake_end, l1_stop, plan.t_y_f, plan.t_y_switch, plan.t_y_end]
    inside = [np.clip(s[:, None] - ages, 0.0, dt) for s in switches]
    expected = np.sort(np.stack([np.zeros_like(ages), *inside, np.full_like(ages, dt)], -1), -1)
    np.testing.assert_allclose(knots, expected, rtol=0, atol=1e-12)
    # At least one switch strictly inside a period for each kind of switch that the scenarios have.
    assert ((knots[..., 1:-1] > 1e-6) & (knots[..., 1:-1] < dt - 1e-6)).any(-1).mean() > 0.5


def test_plan_motion_is_the_plans_motion_with_constant_accelerations_between_knots():
    _, batch, ages, _ = _plans_and_ages()
    dt = PRM.dt
    knots, px, vx, py, vy = plan_motion(batch, ages, dt)
    ref = batch.take((..., None)).state(ages[..., None] + knots)
    for got, want in zip((px, py, vx, vy), ref, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    # Between knots each motion is one constant-acceleration segment: the midpoint is where the segment's
    # quadratic (from its start and its speed change) puts it.
    h = np.diff(knots, axis=-1)
    mid_px, mid_py, _, _ = batch.take((..., None)).state(ages[..., None] + knots[..., :-1] + h / 2)
    for p, v, mid in ((px, vx, mid_px), (py, vy, mid_py)):
        a = np.where(h > 0, np.diff(v, axis=-1) / np.where(h > 0, h, 1.0), 0.0)
        quad = p[..., :-1] + v[..., :-1] * h / 2 + 0.5 * a * (h / 2) ** 2
        np.testing.assert_allclose(mid, quad, rtol=0, atol=1e-9)
