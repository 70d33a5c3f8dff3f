"""Hand-computed golden cases for the safety engine (paper §3.3, Eqs. 1–9), ad-rss style.

Every expected value below is worked out by hand in the comments — none comes from calling the engine. Most
cases use ``GOLDEN``, parameters chosen so the arithmetic stays in round numbers:
``a_x_a = 2``, ``a_x_d = 8``, ``a_y_m = 2`` m/s², ``w_l = 3.5``, ``w_v = 1.5`` m (so ``y_s = (3.5 − 1.5)/2 = 1``),
``p_m = 5``, ``p_m_human = 10`` m. The named scenarios of ``scenarios.py`` (default parameters) are checked for
the outcome their names promise at the end.
"""

from __future__ import annotations

import numpy as np
import pytest

import scenarios
from safelane import Params
from safelane.safety import (
    Reason,
    evasion_exists,
    follower_position,
    lateral_evasion_time,
    leader_chain,
    longitudinal_evasion,
    plan_evasion,
    worst_case_leader_decel,
)

GOLDEN = Params(
    a_x_a=2.0, a_x_d=8.0, a_y_m=2.0, lane_width=3.5, vehicle_width=1.5, vehicle_length=4.5, p_m=5.0, p_m_human=10.0
)
DEFAULT = Params()
EXACT = dict(rel=1e-12, abs=1e-12)


def _min_gap_time_stepped(gap0, v_follow, z, v_lead, a_lead, dt=1e-4, horizon=10.0):
    """Smallest gap between a follower braking at ``z`` and a leader braking at ``a_lead`` (both stop at rest),
    by stepping time; independent of the engine."""
    gap, vf, vl, smallest = gap0, v_follow, v_lead, gap0
    for _ in range(int(horizon / dt)):
        new_vf, new_vl = max(vf - z * dt, 0.0), max(vl - a_lead * dt, 0.0)
        gap += 0.5 * (vl + new_vl) * dt - 0.5 * (vf + new_vf) * dt  # exact within a step unless one stops in it
        vf, vl = new_vf, new_vl
        smallest = min(smallest, gap)
        if vf == 0.0 and vl == 0.0:
            break
    return smallest


# --- Eqs. 1–3: the leader chain ---------------------------------------------------------------------------------


def _interior_chain():
    # L3 (unconnected) at 100 m brakes at a_x_d = 8. L2 at 17.5 m, 15 m/s, promise 2: its slack is
    # 100 − 17.5 − 5 = 77.5 m, equal speeds, so Eq. 2's second case: z_2 = 15²/(2·77.5 + 15²/8) = 225/183.125
    # ≈ 1.229 < 2, hence a_2 = max(2, 1.229) = 2.
    # L1 at 0 m, 20 m/s, promise 0: D = 17.5 − 0 − 5 = 12.5, Δv = 20 − 15 = 5; the equal-speed case applies
    # because 2·D·a_2 = 2·12.5·2 = 50 <= v_2·Δv = 15·5 = 75.
    return dict(p=[0.0, 17.5, 100.0], v=[20.0, 15.0, 15.0], promise_decel=[0.0, 2.0])


def test_eq2_first_case_uses_factor_one_half():
    # Corrected Eq. 2, first case: z = a_2 + Δv²/(2D) = 2 + 25/25 = 3.
    result = leader_chain(**_interior_chain(), params=GOLDEN)
    assert result.required[0] == pytest.approx(3.0, **EXACT)
    assert result.decel[:2] == pytest.approx([3.0, 2.0], **EXACT)
    assert result.l1_decel == pytest.approx(3.0, **EXACT)
    assert not result.unsafe


def test_paper_factor_three_is_refuted_by_time_stepping():
    # The paper's Eq. 2 gives z = 3·Δv²/(2D) + a_2 = 3·25/25 + 2 = 5. Eq. 1 asks for the z at which the
    # gap's minimum is exactly p_m. Time-stepping the two vehicles from gap 17.5 m:
    #   z = 3   → speeds equal at t = Δv/(z − a_2) = 5 s; the gap shrinks by Δv²/(2(z − a_2)) = 12.5 to 5 = p_m;
    #   z = 5   → equal at 5/3 s, shrinks by 25/6 ≈ 4.17 → min gap ≈ 13.33 m, far above p_m: not a root of Eq. 1;
    #   z = 2.9 → shrinks by 25/1.8 ≈ 13.89 → min gap ≈ 3.61 < p_m, so anything below 3 collides: 3 is the answer.
    paper_z = 3 * 5.0**2 / (2 * 12.5) + 2.0
    assert paper_z == 5.0
    assert _min_gap_time_stepped(17.5, 20.0, 3.0, 15.0, 2.0) == pytest.approx(5.0, abs=1e-3)
    assert _min_gap_time_stepped(17.5, 20.0, paper_z, 15.0, 2.0) == pytest.approx(17.5 - 25 / 6, abs=1e-3)
    assert _min_gap_time_stepped(17.5, 20.0, 2.9, 15.0, 2.0) == pytest.approx(17.5 - 25 / 1.8, abs=1e-3)
    assert leader_chain(**_interior_chain(), params=GOLDEN).required[0] != pytest.approx(paper_z)


def test_eq2_second_case_equal_speeds():
    # L1 at 0 m and L2 (unconnected, a_x_d = 8) at 30 m, both at 20 m/s: D = 30 − 5 = 25, Δv = 0 → second case:
    # z = v_1²/(2D + v_2²/a_x_d) = 400/(50 + 50) = 4. With promise 2, a_1 = max(2, 4) = 4; with promise 6, 6.
    assert worst_case_leader_decel([0.0, 30.0], [20.0, 20.0], [2.0], GOLDEN) == pytest.approx(4.0, **EXACT)
    assert worst_case_leader_decel([0.0, 30.0], [20.0, 20.0], [6.0], GOLDEN) == pytest.approx(6.0, **EXACT)


def test_eq2_second_case_when_leader_stops_before_speeds_meet():
    # L1 20 m/s, L2 10 m/s at a_x_d = 8, D = 25 − 5 = 20. 2·D·a = 320 > v_2·Δv = 10·10 = 100, so L2 stops
    # (after 1.25 s) before the speeds meet: z = 400/(2·20 + 100/8) = 400/52.5 = 160/21 ≈ 7.619.
    # Check: L1 brakes 400/(2z) = 26.25 m, L2 100/16 = 6.25 m; the gap shrinks by 20 = D. (The first-case formula
    # would give 8 + 100/40 = 10.5 and declare the link unsafe.)
    result = leader_chain([0.0, 25.0], [20.0, 10.0], [0.0], GOLDEN)
    assert result.required[0] == pytest.approx(160 / 21, **EXACT)
    assert not result.unsafe
    assert _min_gap_time_stepped(25.0, 20.0, 160 / 21, 10.0, 8.0, dt=1e-5) == pytest.approx(5.0, abs=1e-3)


def test_no_connected_leader_means_mechanical_limit():
    # N = 0: L1 is the unconnected L(N+1), which may brake at a_x_d = 8.
    assert worst_case_leader_decel([50.0], [20.0], np.zeros(0), GOLDEN) == 8.0


@pytest.mark.parametrize(
    ("p", "v", "why"),
    [
        ([0.0, 5.0], [21.0, 20.0], "gap 5 − 0 − p_m = 0: at the margin and closing at 1 m/s"),
        ([0.0, 4.9], [20.0, 20.0], "gap 4.9 − 0 − p_m = −0.1: inside the margin"),
        ([0.0, 10.0], [20.0, 10.0], "D = 5, 2·5·8 = 80 <= 10·10: z = 8 + 100/10 = 18 > a_x_d"),
    ],
)
def test_unsafe_chain_gives_mechanical_limit_and_reason_bit(p, v, why):
    result = leader_chain(p, v, [1.0], GOLDEN)
    assert result.unsafe, why
    assert result.l1_decel == 8.0
    assert not np.isnan(result.decel).any()
    plan = plan_evasion(0.0, 2.0, 20.0, 2.0, 50.0, 20.0, result.l1_decel, -40.0, 20.0, False, GOLDEN,
                        chain_unsafe=result.unsafe)  # fmt: skip
    assert plan.reason & Reason.CHAIN_UNSAFE


def test_at_the_margin_and_not_closing_the_link_is_safe():
    # gap 5 − 0 − p_m = 0 at equal speeds 20 m/s, L2 at a_x_d = 8: braking like L2 keeps the gap exactly, so
    # z = 8 (the slack -> 0+ limit of z_B = 400 / (2·0 + 400/8)), not "unsafe" (the jump the adversarial search hit).
    result = leader_chain([0.0, 5.0], [20.0, 20.0], [1.0], GOLDEN)
    assert not result.unsafe
    assert result.l1_decel == pytest.approx(8.0, rel=1e-9)
    # L2 slower by 2 m/s: the gap opens first; z = 8·(18/20)² = 6.48.
    assert leader_chain([0.0, 5.0], [18.0, 20.0], [1.0], GOLDEN).l1_decel == pytest.approx(6.48, rel=1e-9)


def test_z_above_mechanical_limit_is_reported():
    # The second row above: z = 18 is what the link needs; it is kept in `required`, and flags the chain.
    assert leader_chain([0.0, 10.0], [20.0, 10.0], [1.0], GOLDEN).required[0] == pytest.approx(18.0, **EXACT)


def test_human_driven_link_keeps_the_larger_margin():
    # L1 at 0, L2 at 35 m, both 20 m/s, L2 at a_x_d = 8.
    #   machine-driven L1: D = 35 − 5 = 30,  z = 400/(60 + 50) = 40/11 ≈ 3.636;
    #   human-driven L1:   D = 35 − 10 = 25, z = 400/(50 + 50) = 4.
    assert worst_case_leader_decel([0.0, 35.0], [20.0, 20.0], [0.0], GOLDEN) == pytest.approx(40 / 11, **EXACT)
    human = worst_case_leader_decel([0.0, 35.0], [20.0, 20.0], [0.0], GOLDEN, human_driven=[True])
    assert human == pytest.approx(4.0, **EXACT)


# --- Eq. 5: lateral evasion time --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("p_y", "v_y", "t_y_f", "t_switch"),
    [
        # e = 2 − 1 = 1, r = sqrt(a·e + v²/2) = sqrt(2 + 2) = 2: t_1 = (2 + 2)/2 = 2, t_y_f = (2 + 4)/2 = 3.
        # Check: −2 m/s² for 2 s → v = −2, y = 2 + 4 − 4 = 2; +2 m/s² for 1 s → v = 0, y = 2 − 2 + 1 = 1 = y_s.
        (2.0, 2.0, 3.0, 2.0),
        # Inside its lane (e = −0.5) but drifting out fast: s = −0.5 + 4/4 = 0.5 > 0, r = sqrt(−1 + 2) = 1:
        # t_1 = (2 + 1)/2 = 1.5, t_y_f = (2 + 2)/2 = 2.
        (0.5, 2.0, 2.0, 1.5),
        # Standing still 0.5 m out of its lane: r = sqrt(2·0.5) = 1, t_1 = 0.5, t_y_f = 1.
        (1.5, 0.0, 1.0, 0.5),
    ],
)
def test_eq5_bang_bang_times(p_y, v_y, t_y_f, t_switch):
    assert lateral_evasion_time(p_y, v_y, GOLDEN) == pytest.approx((t_y_f, t_switch), **EXACT)


@pytest.mark.parametrize(
    ("p_y", "v_y"),
    [
        (0.5, -0.3),  # inside its lane, moving home
        (0.5, 1.0),  # inside, drifting out but stops laterally at 0.5 + 1/(2·2) = 0.75 <= y_s = 1
        (1.0, 0.0),  # exactly at y_s, at rest
    ],
)
def test_nothing_to_evade(p_y, v_y):
    assert lateral_evasion_time(p_y, v_y, GOLDEN) == (0.0, 0.0)


def test_returning_fast_brakes_lateral_speed_only():
    # e = 1.75 − 1 = 0.75, v = −2: s = 0.75 − 4/4 = −0.25 <= 0, so the ego crosses y_s whatever it does.
    # First root of 0.75 − 2t + t² = 0: t = (2 − sqrt(4 − 3))/2 = 0.5; no switch (t_1 = 0).
    assert lateral_evasion_time(1.75, -2.0, GOLDEN) == pytest.approx((0.5, 0.0), **EXACT)
    # The paper's bang-bang solution has r = sqrt(2·0.75 + 2) = sqrt(3.5) ≈ 1.871 and
    # t_1 = (v + r)/a = (−2 + 1.871)/2 < 0: a switch before t = 0, i.e. no valid solution.
    assert (-2.0 + np.sqrt(3.5)) / 2.0 < 0.0


# --- Eqs. 6–8: longitudinal evasion behind L1 (Figure 3) -------------------------------------------------------


@pytest.mark.parametrize(
    ("case", "state", "t_x1", "t_x2", "min_gap"),
    [
        # 0, accelerate throughout: ego 0 m at 20 m/s, L1 at 100 m, 20 m/s braking at 8, T = 2. At T the ego is
        # at 40 + 4 = 44, L1 at 100 + 40 − 16 = 124 (still moving): gap 80 >= 5; at 0 the gap is 100.
        (0, (0.0, 20.0, 100.0, 20.0, 8.0, 2.0), 2.0, 2.0, 80.0),
        # 1, still braking at T: ego 20 m/s, L1 at 12 m, 20 m/s at 4, T = 2. u = 1: ego at 21 m, 22 m/s; braking
        # 1 s at 8 → 21 + 22 − 4 = 39 m, 14 m/s. L1 at 12 + 40 − 8 = 44 m, 12 m/s (slower: no match; the speeds
        # would meet at 2.5 s). Gap at T = 44 − 39 = 5 = p_m. Eq. 7 first case: R = 44 − 5 − 0 − 40 = −1,
        # u = 2 − sqrt(4 − (8·4 − 2)/10) = 2 − 1 = 1. t_x2 = min(2.5, T) = 2.
        (1, (0.0, 20.0, 12.0, 20.0, 4.0, 2.0), 1.0, 2.0, 5.0),
        # 2, stopped before T after L1: ego 8 m/s, L1 at 19.25 m, 4 m/s at 8 (stops after 1 m at 0.5 s), T = 3.
        # u = 1: ego at 9 m, 10 m/s; brakes 10/8 = 1.25 s and 100/16 = 6.25 m → rests at 15.25 m at 2.25 s.
        # Gap 19.25 + 1 − 15.25 = 5. Eq. 7 second case: p_1^stop = 20.25, (v² + 2·8·(0 + 5 − 20.25))/(10·2)
        # = (64 − 244)/20 = −9, u = −4 + sqrt(16 + 9) = 1.
        (2, (0.0, 8.0, 19.25, 4.0, 8.0, 3.0), 1.0, 2.25, 5.0),
        # 3, following a moving L1: ego 22 m/s, L1 at 12 m, 20 m/s at 2 (stops at 10 s), T = 3. u = 1: ego at
        # 23 m, 24 m/s; L1 at 31 m, 18 m/s; relative speed 6 closes at 8 − 2 = 6 m/s² → match at t_x2 = 2, both
        # at 16 m/s, ego 23 + 24 − 4 = 43 m, L1 12 + 40 − 4 = 48 m: gap 5, frozen from then on.
        # Eq. 7 third case: w = 2, k = 4, C_2 = (4 − 2·7·6)/(2·10) = −4, u = (−2 + sqrt(4 + 32))/4 = 1.
        (3, (0.0, 22.0, 12.0, 20.0, 2.0, 3.0), 1.0, 2.0, 5.0),
        # 4, following L1 to a stop: ego and L1 at 12 m/s, L1 at 12.5 m braking at 4 (stops at 3 s), T = 4.
        # u = 1: ego at 13 m, 14 m/s; L1 at 22.5 m, 8 m/s; relative speed 6 closes at 4 m/s² → match at 2.5 s at
        # 2 m/s, ego 13 + 21 − 9 = 25 m, L1 12.5 + 30 − 12.5 = 30 m: gap 5; both stop at 3 s, 0.5 m later.
        # C_2 = (0 − 2·7.5·4)/20 = −3, u = sqrt(0 + 2·6·3)/6 = 1 (same formula as case 3).
        (4, (0.0, 12.0, 12.5, 12.0, 4.0, 4.0), 1.0, 2.5, 5.0),
        # −1, infeasible: L1 4 m ahead, gap already 1 m inside p_m; the reported minimum is the initial 4 m.
        (-1, (0.0, 20.0, 4.0, 20.0, 8.0, 2.0), 0.0, 0.0, 4.0),
    ],
)
def test_longitudinal_figure3_cases(case, state, t_x1, t_x2, min_gap):
    result = longitudinal_evasion(*state, GOLDEN)
    assert result.case == case
    assert bool(result.feasible) == (case != -1)
    assert result.t_x1 == pytest.approx(t_x1, **EXACT)
    assert result.t_x2 == pytest.approx(t_x2, **EXACT)
    assert result.min_gap == pytest.approx(min_gap, **EXACT)


# --- Eq. 9 and the full check -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("v", "aggressive", "expected"),
    [
        (20.0, True, 24.0),  # −20 + 20·2 + 2·2²/2 = 24
        (20.0, False, 4.0),  # −20 + 20·2 − 8·2²/2 = 4 (still moving: stops at 2.5 s)
        (8.0, False, -16.0),  # stops after 8/8 = 1 s and 64/16 = 4 m: −20 + 4 = −16
        (8.0, True, -0.0),  # −20 + 16 + 4 = 0: an aggressive follower never stops
    ],
)
def test_eq9_follower_position(v, aggressive, expected):
    assert follower_position(-20.0, v, aggressive, 2.0, GOLDEN) == pytest.approx(expected, **EXACT)


def _far_leader(**follower):
    # Lateral (2, 2) → T = 3 (above). Ego at 0 m, 10 m/s; L1 1 km ahead: the ego accelerates throughout,
    # x(t) = 10t + t².
    return dict(ego_px=0.0, ego_py=2.0, ego_vx=10.0, ego_vy=2.0, l1_p=1000.0, l1_v=30.0, l1_decel=8.0, **follower)


@pytest.mark.parametrize(("f_p", "exists", "min_gap"), [(-10.0, True, 5.0), (-9.9, False, 4.9)])
def test_collaborative_follower_closest_at_equal_speeds(f_p, exists, min_gap):
    # Follower at 20 m/s braking at 8: x_f(t) = f_p + 20t − 4t² (stops at 2.5 s). Ego − follower
    # = −f_p − 10t + 5t², smallest where the speeds are equal, t = (20 − 10)/(2 + 8) = 1: −f_p − 5.
    # f_p = −10 → 5 = p_m (kept); f_p = −9.9 → 4.9 (not kept). The ends are harmless: 10 at t = 0 and, at
    # t = 3, 39 − (f_p + 25) = 24 — a check at 0, T and breakpoints alone would miss the violation.
    plan = plan_evasion(**_far_leader(f_p=f_p, f_v=20.0, follower_aggressive=False), params=GOLDEN)
    assert bool(plan.feasible) is exists
    assert plan.min_gap_follower == pytest.approx(min_gap, **EXACT)
    assert plan.reason == (Reason.OK if exists else Reason.FOLLOWER_TOO_CLOSE)


@pytest.mark.parametrize(("f_p", "exists"), [(-65.0, True), (-64.9, False)])
def test_aggressive_follower_closest_at_horizon(f_p, exists):
    # Follower at 30 m/s accelerating at 2 like the ego (10 m/s): ego − follower = −f_p + (10 − 30)t shrinks
    # linearly to −f_p − 60 at T = 3: 5 = p_m for f_p = −65, 4.9 for −64.9.
    state = _far_leader(f_p=f_p, f_v=30.0, follower_aggressive=True)
    assert evasion_exists(**state, params=GOLDEN) == exists
    assert plan_evasion(**state, params=GOLDEN).min_gap_follower == pytest.approx(-f_p - 60.0, **EXACT)


@pytest.mark.parametrize(("f_p", "exists"), [(-15.0, True), (-14.9, False)])
def test_human_driven_follower_margin(f_p, exists):
    # As the collaborative case, with p_m_human = 10: closest approach −f_p − 5 must be >= 10.
    state = _far_leader(f_p=f_p, f_v=20.0, follower_aggressive=False)
    assert evasion_exists(**state, params=GOLDEN, follower_human=True) == exists
    assert evasion_exists(**state, params=GOLDEN)  # p_m = 5 is kept either way


def test_human_driven_leader_margin():
    # Figure-3 case 1 above with p_m_human = 10 instead of 5 moves L1 5 m further ahead for the same u = 1:
    # L1 at 17 m. Lateral (0.5, 2) → T = 2 (above).
    state = dict(ego_px=0.0, ego_py=0.5, ego_vx=20.0, ego_vy=2.0, l1_p=17.0, l1_v=20.0, l1_decel=4.0,
                 f_p=-100.0, f_v=20.0, follower_aggressive=False)  # fmt: skip
    plan = plan_evasion(**state, params=GOLDEN, leader_human=True)
    assert plan.t_y_f == pytest.approx(2.0, **EXACT)
    assert plan.t_x1 == pytest.approx(1.0, **EXACT)
    assert plan.min_gap_leader == pytest.approx(10.0, **EXACT)


def test_nothing_to_evade_exists_whatever_the_surroundings():
    # Ego inside its lane (p_y = 0.5 < y_s = 1) moving home: t_y_f = 0, even with a follower 1 m behind.
    plan = plan_evasion(0.0, 0.5, 20.0, -0.3, 6.0, 10.0, 8.0, -1.0, 30.0, True, GOLDEN)
    assert plan.feasible
    assert plan.t_y_f == 0.0
    assert plan.reason & Reason.NOTHING_TO_EVADE


# --- EvasionPlan ------------------------------------------------------------------------------------------------


def _plans():
    states = [scenarios.EVASION_SCENARIOS[name]() for name in sorted(scenarios.EVASION_SCENARIOS)]
    batch = {k: np.array([s[k] for s in states]) for k in states[0]}
    return batch, plan_evasion(**batch, params=DEFAULT)


def test_plan_state_at_zero_is_the_input_state():
    batch, plan = _plans()
    px, py, vx, vy = plan.state(0.0)
    np.testing.assert_array_equal(px, batch["ego_px"])
    np.testing.assert_array_equal(py, batch["ego_py"])
    np.testing.assert_array_equal(vx, batch["ego_vx"])
    np.testing.assert_array_equal(vy, batch["ego_vy"])


@pytest.mark.parametrize("switch", ["t_y_switch", "t_x1", "t_x2", "t_y_f"])
def test_plan_is_continuous_at_switch_times(switch):
    # Position and speed are continuous (accelerations are bounded): across ±eps they move by O(eps).
    _, plan = _plans()
    eps = 1e-7
    t = getattr(plan, switch)
    before = plan.state(np.maximum(t - eps, 0.0))
    after = plan.state(t + eps)
    for a, b in zip(before, after, strict=True):
        np.testing.assert_allclose(a, b, atol=100 * eps)


def test_plan_ends_at_rest_in_the_original_lane():
    # The lateral profile ends at y_s with zero lateral speed after a bang-bang return (Eq. 5).
    plan = plan_evasion(**_far_leader(f_p=-40.0, f_v=20.0, follower_aggressive=False), params=GOLDEN)
    _, py, _, vy = plan.state(plan.t_y_f)
    assert py == pytest.approx(1.0, **EXACT)
    assert vy == pytest.approx(0.0, abs=1e-12)
    # x(T) = 10·3 + 3² = 39 and v = 16 on the accelerate-throughout profile; after T it holds its speed.
    px, _, vx, _ = plan.state(4.0)
    assert (px, vx) == pytest.approx((39.0 + 16.0, 16.0), **EXACT)


# --- the named scenarios keep their promises --------------------------------------------------------------------

SCENARIO_OUTCOMES = {
    # name: (exists, reason bits, Figure-3 case code)
    "open_gap_collaborative_follower": (True, Reason.OK, 0),
    "tight_gap_aggressive_follower": (False, Reason.FOLLOWER_TOO_CLOSE, 0),
    "leader_braking_hard_close": (False, Reason.LEADER_INFEASIBLE, -1),
    "already_back_in_lane": (True, Reason.NOTHING_TO_EVADE, 0),
    "past_lane_boundary_returning_fast": (True, Reason.OK, 0),
    "ego_stops_before_horizon": (True, Reason.OK, 2),
    "follow_l1_to_stop": (True, Reason.OK, 4),
    "follow_moving_l1": (True, Reason.OK, 3),
    "still_braking_at_horizon": (True, Reason.OK, 1),
    "collaborative_follower_stops_behind": (True, Reason.OK, 0),
    "human_driven_follower_needs_larger_margin": (True, Reason.OK, 0),
}


def test_every_scenario_has_an_outcome():
    assert set(SCENARIO_OUTCOMES) == set(scenarios.EVASION_SCENARIOS)


@pytest.mark.parametrize("name", sorted(SCENARIO_OUTCOMES))
def test_scenario_outcome(name):
    state = scenarios.EVASION_SCENARIOS[name]()
    exists, reason, case = SCENARIO_OUTCOMES[name]
    plan = plan_evasion(**state, params=DEFAULT)
    assert evasion_exists(**state, params=DEFAULT) == exists
    assert plan.reason == reason
    lon = longitudinal_evasion(state["ego_px"], state["ego_vx"], state["l1_p"], state["l1_v"], state["l1_decel"],
                               plan.t_y_f, DEFAULT)  # fmt: skip
    assert lon.case == case


def test_returning_fast_scenario_has_no_lateral_switch():
    plan = plan_evasion(**scenarios.past_lane_boundary_returning_fast(), params=DEFAULT)
    assert plan.t_y_f > 0.0
    assert plan.t_y_switch == 0.0


def test_follower_scenarios_bind_where_named():
    stops = plan_evasion(**scenarios.collaborative_follower_stops_behind(), params=DEFAULT)
    # Ego 3 m/s accelerating at 2.5, follower 6 m/s braking at 8: equal speeds at 3/10.5 s, closing
    # 3·(3/10.5)/2 = 3/7 m: 9 − 3/7 ≈ 8.571 m, an interior minimum.
    assert stops.min_gap_follower == pytest.approx(9.0 - 3.0 / 7.0, **EXACT)
    human = scenarios.human_driven_follower_needs_larger_margin()
    assert evasion_exists(**human, params=DEFAULT)
    assert not evasion_exists(**human, params=DEFAULT, follower_human=True)


def test_chain_scenarios():
    a_x_d = DEFAULT.a_x_d
    below = leader_chain(**scenarios.chain_gap_below_margin(), params=DEFAULT)
    assert below.unsafe and below.l1_decel == a_x_d and np.isinf(below.required[0])
    absorbs = leader_chain(**scenarios.connected_chain_absorbs_braking(), params=DEFAULT)
    assert not absorbs.unsafe and absorbs.l1_decel < absorbs.decel[1] < a_x_d
    link = scenarios.human_driven_link_needs_larger_margin()
    assert not leader_chain(**link, params=DEFAULT).unsafe
    assert leader_chain(**link, params=DEFAULT, human_driven=[True]).unsafe
    closing = leader_chain(**scenarios.closing_fast_on_braking_leader(), params=DEFAULT)
    assert closing.unsafe and closing.required[0] == pytest.approx(8.0 + 100.0 / 16.0, **EXACT)
    assert worst_case_leader_decel(**scenarios.unconnected_leader_only(), params=DEFAULT) == a_x_d
