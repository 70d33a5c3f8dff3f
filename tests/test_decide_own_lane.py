"""The shield's decision with a leader L0 in the ego's own lane (``check_candidate(..., own=...)``, issue 17).

The reference is independent of the library: with L1 and F far away, a proposal is safe iff (1) the ego's gap to L0
braking at its worst case stays >= p_m during the period (exact minimum of a quadratic), and (2) from the period's
end the ego can keep p_m behind L0 by braking at a_x_d — checked here by time stepping both vehicles to a stop on a
fine grid (braking to rest and following L0 have the same minimum gap: they coincide until the speeds meet).
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.safety.longitudinal import FEASIBILITY_TOL_M
from safelane.shield.decide import check_candidate, own_completion_level
from safelane.shield.policies import COMPLETION_RULES

PRM = Params()
FAR = 1e4


def _run(ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l0_x, l0_v, l0_decel, prm=PRM):
    n = len(ego_x)
    far = np.full(n, FAR)
    args = (ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, far, np.full(n, 30.0), np.zeros(n), -far, np.zeros(n),
            np.zeros(n, bool))  # fmt: skip
    return check_candidate(*args, prm, own=(l0_x, l0_v, l0_decel))


def _ref_min_gap(gap0, ve, a_e, v0, a0, t_end, prm=PRM, h=2e-4):
    """Minimum of x0 - x over [0, t_end] by time stepping (ego accelerating at a_e, L0 at -a0, both stop at rest)."""
    t = np.arange(0.0, t_end + h, h)
    te = np.where(a_e < 0, np.minimum(t, ve / -a_e if a_e < 0 else np.inf), t)
    xe = ve * te + 0.5 * a_e * te * te
    t0 = np.minimum(t, v0 / a0) if a0 > 0 else t
    x0 = gap0 + v0 * t0 - 0.5 * a0 * t0 * t0
    return float((x0 - xe).min())


def _reference(gap, ve, v0, a_x, a0, prm=PRM):
    """Safe by (1) and (2) of the module docstring, with margins of 1 mm kept apart from the boundary."""
    dt = prm.dt
    in_period = _ref_min_gap(gap, ve, a_x, v0, a0, dt)
    te = min(dt, ve / -a_x) if a_x < 0 else dt
    xe, ve1 = ve * te + 0.5 * a_x * te * te, max(ve + a_x * te, 0.0)
    t0 = min(dt, v0 / a0) if a0 > 0 else dt
    x0, v01 = gap + v0 * t0 - 0.5 * a0 * t0 * t0, max(v0 - a0 * t0, 0.0)
    horizon = max(ve1 / prm.a_x_d, v01 / a0 if a0 > 0 else 0.0) + 1.0
    after = _ref_min_gap(x0 - xe, ve1, -prm.a_x_d, v01, a0, horizon)
    return min(in_period, after) - prm.p_m


def test_own_lane_decisions_match_an_independent_reference():
    rng = np.random.default_rng(17)
    n = 400
    gap = rng.uniform(PRM.p_m - 1.0, 22.0, n)
    ve = rng.uniform(5.0, 30.0, n)
    v0 = np.maximum(ve + rng.uniform(-6.0, 4.0, n), 0.0)
    a_x = rng.choice([PRM.a_x_a, 0.0, -3.0], n)
    a0 = rng.choice([PRM.a_x_d, 4.0, 1.0], n)
    ey, evy = np.full(n, 0.2), np.full(n, 0.3)  # leaving the lane: every row is checked with L0
    got = _run(np.zeros(n), ey, ve, evy, a_x, np.zeros(n), gap, v0, a0)
    ref = np.array([_reference(*row) for row in zip(gap, ve, v0, a_x, a0, strict=True)])
    clear = np.abs(ref) > 1e-3
    assert clear.sum() > 300 and 0.2 < (ref[clear] >= 0).mean() < 0.9  # both verdicts well represented
    np.testing.assert_array_equal(got.ok[clear], ref[clear] >= 0)


def test_rows_without_l0_are_decided_as_without_own_lane_fields():
    rng = np.random.default_rng(3)
    n = 64
    ve = rng.uniform(5.0, 30.0, n)
    args = (np.zeros(n), rng.uniform(0.0, 1.5, n), ve, rng.uniform(-0.5, 1.0, n), rng.uniform(-4.0, 2.5, n),
            rng.uniform(-1.5, 1.5, n), rng.uniform(8.0, 40.0, n), ve + rng.uniform(-3, 3, n), rng.uniform(0, 8, n),
            -rng.uniform(8.0, 40.0, n), ve + rng.uniform(-3, 3, n), rng.random(n) < 0.5)  # fmt: skip
    plain = check_candidate(*args, PRM)
    # Half the rows get a real L0 far ahead (the decision may differ only in the plan's continuation), half none.
    own_x = np.where(np.arange(n) % 2 == 0, np.inf, 1e3)
    mixed = check_candidate(*args, PRM, own=(own_x, ve, np.full(n, PRM.a_x_d)))
    none_rows = np.arange(n) % 2 == 0
    np.testing.assert_array_equal(mixed.ok[none_rows], plain.ok[none_rows])
    np.testing.assert_array_equal(mixed.completing[none_rows], plain.completing[none_rows])
    assert mixed.ok[~none_rows].sum() > 0


def test_all_rows_with_l0_are_checked():
    """Every row has L0 far ahead and the ego keeps to its lane: the proposals are safe and accepted (a batch with
    no row for the paper's groups)."""
    n = 5
    got = _run(np.zeros(n), np.zeros(n), np.full(n, 20.0), np.zeros(n), np.full(n, 1.0), np.zeros(n),
               np.full(n, 200.0), np.full(n, 20.0), np.full(n, PRM.a_x_d))  # fmt: skip
    assert got.ok.all()


def test_l0_period_gap_tolerance_is_half_the_feasibility_tolerance():
    """L0 cruising (worst case 0: a connected L0 promising nothing harder), the ego faster by 0.5 m/s braking at
    8 m/s²: the gap dips by exactly 0.015625 m at t = 0.0625 s, inside the period, then grows; from the period's end
    the ego follows L0 easily. So only the in-period check decides: a dip to −0.25 nm is accepted, to −1 nm refused
    (the check keeps half of the 1 nm tolerance for L0)."""
    dip = 0.25 / (2.0 * 8.0)  # Δv² / (2 a), exact in binary
    for below, accepted in ((0.25e-9, True), (1.0e-9, False), (0.0, True)):
        gap = PRM.p_m + dip - below
        got = _run(np.zeros(1), np.zeros(1), np.full(1, 20.5), np.zeros(1), np.full(1, -8.0), np.zeros(1),
                   np.full(1, gap), np.full(1, 20.0), np.zeros(1))  # fmt: skip
        assert got.ok[0] == accepted, below
    assert FEASIBILITY_TOL_M == 1e-9


def test_l0_period_gap_exactly_half_the_tolerance_inside_p_m_is_kept():
    """The boundary itself: a gap to L0 exactly ½ nm inside ``p_m`` counts as kept (``>=``), one ulp further does
    not. Exact only where positions are of the tolerance's magnitude: all at rest, ``p_m = 2^-30`` m (so ``x - p_m``
    is exact) and a sub-nanometre car; the evasion from the period's end keeps ``p_m + ½ tol`` to L0, met there
    within its own tolerance, so the in-period check alone decides."""
    tiny = Params(vehicle_length=4e-10, p_m=2.0**-30, p_m_human=2.0**-30)
    at_tie = tiny.p_m - 0.5 * FEASIBILITY_TOL_M
    assert at_tie - tiny.p_m == -0.5 * FEASIBILITY_TOL_M
    z = np.zeros(1)
    for l0_x, accepted in ((at_tie, True), (np.nextafter(at_tie, -1.0), False), (np.nextafter(at_tie, 1.0), True)):
        got = _run(z, z, z, z, z, z, np.full(1, l0_x), z, z, prm=tiny)
        assert got.ok[0] == accepted, l0_x - tiny.p_m


def test_l0_is_predicted_braking_at_its_worst_case():
    """The same proposal is safe behind an L0 that may brake at 1 m/s² and unsafe behind one that may brake at
    a_x_d (kills a sign error in L0's predicted motion)."""
    got = _run(np.zeros(2), np.zeros(2), np.full(2, 20.0), np.zeros(2), np.full(2, PRM.a_x_a), np.zeros(2),
               np.full(2, 9.0), np.full(2, 20.0), np.array([1.0, PRM.a_x_d]))  # fmt: skip
    assert got.ok[0] and not got.ok[1]


def test_with_l0_completion_needs_the_level_and_no_drift_back():
    level = own_completion_level(PRM)
    assert level == max(PRM.y_boundary, PRM.vehicle_width)
    # Ends the period at the level moving away (0.5 m/s) or still (0): completing; drifting back: not.
    rows = []
    for vy1 in (0.5, 0.0, -0.2):
        a_y = 0.0
        y0 = level - vy1 * PRM.dt
        rows.append((y0, vy1, a_y))
    y0, vy, ay = (np.array(c) for c in zip(*rows, strict=True))
    got = _run(np.zeros(3), y0, np.full(3, 20.0), vy, np.zeros(3), ay, np.full(3, 300.0), np.full(3, 20.0),
               np.full(3, PRM.a_x_d))  # fmt: skip
    assert got.completing.tolist() == [True, True, False]
    # Without L0 the paper's level applies: the boundary.
    plain = check_candidate(np.zeros(1), np.array([PRM.y_boundary]), np.full(1, 20.0), np.zeros(1), np.zeros(1),
                            np.zeros(1), np.full(1, FAR), np.full(1, 30.0), np.zeros(1), np.full(1, -FAR),
                            np.zeros(1), np.zeros(1, bool), PRM)  # fmt: skip
    assert plain.completing[0]


def test_target_lane_period_checks_still_apply_beside_l0_rows():
    """A batch mixing a row without L0 whose F gap dips below p_m inside the period (refused by the target lane's
    period check) with a row that has L0 far ahead: the L0 check adds to the target lane's checks, it does not
    replace them."""
    from test_decide import ORDER, follower_gap_dips_inside_the_period

    dip = follower_gap_dips_inside_the_period(0.005)
    state = {k: np.concatenate([v, v]) for k, v in dip.items()}
    own = (np.array([np.inf, 500.0]), np.array([20.0, 20.0]), np.array([PRM.a_x_d, PRM.a_x_d]))
    got = check_candidate(*(state[k] for k in ORDER), PRM, own=own)
    assert not got.ok[0] and not got.ok[1]  # the dip is in both rows; L0 far ahead changes nothing


def test_positions_are_relative_to_the_ego():
    """The same situation shifted 1 km down the road decides the same."""
    args = (np.full(1, 20.0), np.zeros(1), np.full(1, PRM.a_x_a), np.zeros(1), np.full(1, 9.0), np.full(1, 20.0),
            np.full(1, PRM.a_x_d))  # fmt: skip
    ve, vy, ax, ay, gap, v0, a0 = args
    near = _run(np.zeros(1), np.zeros(1), ve, vy, ax, ay, gap, v0, a0)
    far = _run(np.full(1, 1000.0), np.zeros(1), ve, vy, ax, ay, gap + 1000.0, v0, a0)
    assert not near.ok[0] and not far.ok[0]
    ok_near = _run(np.zeros(1), np.zeros(1), ve, vy, np.zeros(1), ay, np.full(1, 40.0), v0, a0)
    ok_far = _run(np.full(1, 1000.0), np.zeros(1), ve, vy, np.zeros(1), ay, np.full(1, 1040.0), v0, a0)
    assert ok_near.ok[0] and ok_far.ok[0]


def test_l0_braking_inside_the_period_is_its_worst_case():
    """The ego (braking at a_x_d) 0.2 m/s faster than L0 braking at 4: relative deceleration 4, the gap dips by
    0.2²/(2·4) = 5 mm at t = 0.05 s and recovers by the period's end, from where the ego easily stays behind.
    Starting 4 mm above p_m the dip goes 1 mm below: refused. (Were L0 predicted to *accelerate* at 4 the dip would
    be 1.7 mm and the proposal accepted.)"""
    for x0 in (0.0, 1000.0):  # anywhere on the road: the gap is L0's position minus the ego's
        for extra, accepted in ((0.004, False), (0.008, True)):
            got = _run(np.full(1, x0), np.zeros(1), np.full(1, 20.2), np.zeros(1), np.full(1, -PRM.a_x_d),
                       np.zeros(1), np.full(1, x0 + PRM.p_m + extra), np.full(1, 20.0), np.full(1, 4.0))  # fmt: skip
            assert got.ok[0] == accepted, (x0, extra)


def test_an_own_lane_with_no_vehicle_in_any_row_decides_as_none():
    rng = np.random.default_rng(5)
    n = 16
    ve = rng.uniform(5.0, 30.0, n)
    args = (np.zeros(n), rng.uniform(0.0, 1.5, n), ve, rng.uniform(-0.5, 1.0, n), rng.uniform(-4.0, 2.5, n),
            rng.uniform(-1.5, 1.5, n), rng.uniform(8.0, 40.0, n), ve, rng.uniform(0, 8, n), -rng.uniform(8.0, 40.0, n),
            ve, rng.random(n) < 0.5)  # fmt: skip
    plain = check_candidate(*args, PRM)
    empty = check_candidate(*args, PRM, own=(np.full(n, np.inf), np.zeros(n), np.full(n, PRM.a_x_d)))
    np.testing.assert_array_equal(empty.ok, plain.ok)
    np.testing.assert_array_equal(empty.completing, plain.completing)


def test_with_l0_the_boundary_alone_does_not_complete():
    """Past the lane boundary but still within a car's width of L0's lane: not complete (without L0 it would be)."""
    y_end = 0.5 * (PRM.y_boundary + PRM.vehicle_width)
    assert PRM.y_boundary < y_end < own_completion_level(PRM)
    got = _run(np.zeros(1), np.full(1, y_end - 0.05), np.full(1, 20.0), np.full(1, 0.5), np.zeros(1), np.zeros(1),
               np.full(1, 300.0), np.full(1, 20.0), np.full(1, PRM.a_x_d))  # fmt: skip
    assert not got.completing[0]


def test_plans_of_l0_rows_continue_and_know_l0():
    """The plan verified for a row with L0 goes on after t_y_f and carries L0's predicted state (an abort must keep
    following or braking behind it); a row without L0 keeps the paper's plan."""
    n = 2
    got = _run(np.zeros(n), np.full(n, 0.2), np.full(n, 20.0), np.full(n, 0.3), np.zeros(n), np.zeros(n),
               np.array([np.inf, 60.0]), np.full(n, 20.0), np.full(n, PRM.a_x_d))  # fmt: skip
    assert got.ok.all()
    plans = {int(r): (plan, i) for rows, plan in got.plans for i, r in enumerate(rows)}
    plan, i = plans[1]
    assert plan.continues[i] and np.isfinite(plan.own_p[i])
    assert plan.own_p[i] == 60.0 + 20.0 * PRM.dt - 0.5 * PRM.a_x_d * PRM.dt**2
    plan0, j = plans[0]
    assert not plan0.continues[j] and np.isinf(plan0.own_p[j])


def test_the_margin_to_l0_keeps_half_the_tolerance():
    """docs/real_roads.md: the evasion keeps p_m plus half of the 1 nm tolerance to L0, leaving the other half to
    the executor's round-off."""
    from safelane.shield.decide import own_margin

    assert abs((own_margin(PRM) - PRM.p_m) - 0.5 * FEASIBILITY_TOL_M) < 1e-14


def _far_l0(s, rows):
    """``own`` with an L0 1 km ahead of the ego at its speed in ``rows`` (irrelevant to every verdict there) and none
    elsewhere."""
    l0_x = np.where(rows, s["ego_x"] + 1e3, np.inf)
    return l0_x, s["ego_vx"].copy(), np.full(len(rows), PRM.a_x_d)


def test_a_far_l0_changes_no_verdict_of_rows_that_do_not_complete_whatever_f_is():
    """The rows with L0 take F's worst case as the rows without do: with an L0 too far ahead to matter and steps that
    stay below both completion levels, every verdict is the one without L0 — for an aggressive F close behind too
    (run on whichever path the environment selects: NumPy under mutation testing)."""
    from test_decide import ORDER, _states

    rng = np.random.default_rng(28)
    s = _states(3000, rng)
    s["ego_y"] = rng.uniform(0.0, 0.8, 3000)  # far below the boundary: no step completes
    s["ego_vy"] = rng.uniform(-0.5, 0.8, 3000)
    args = [s[k] for k in ORDER]
    plain = check_candidate(*args, PRM)
    own = check_candidate(*args, PRM, own=_far_l0(s, np.ones(3000, bool)))
    assert not plain.completing.any()
    np.testing.assert_array_equal(own.ok, plain.ok)
    # F's type decides some rows here, so a check that ignored it with L0 would differ
    flipped = check_candidate(*args[:11], ~np.asarray(s["f_aggressive"], bool), PRM)
    assert (flipped.ok != plain.ok).sum() > 20


@pytest.mark.parametrize("rule", sorted(COMPLETION_RULES))
def test_rows_without_l0_in_a_mixed_batch_keep_the_completion_rule(rule):
    """In a batch where some rows have L0, the others are decided under the completion rule asked for — the verdicts
    and completions of a batch without L0 under that rule, which differ from the default rule's in some rows."""
    from test_decide import ORDER, _states

    rng = np.random.default_rng(29)
    n = 3000
    s = _states(n, rng)
    s["ego_y"] = rng.uniform(PRM.y_boundary - 0.3, PRM.y_boundary + 0.05, n)  # steps across the boundary
    s["ego_vy"] = rng.uniform(0.0, 1.5, n)
    args = [s[k] for k in ORDER]
    with_l0 = rng.random(n) < 0.3
    completion = COMPLETION_RULES[rule]
    mixed = check_candidate(*args, PRM, completion=completion, own=_far_l0(s, with_l0))
    alone = check_candidate(*args, PRM, completion=completion)
    rows = ~with_l0
    np.testing.assert_array_equal(mixed.ok[rows], alone.ok[rows])
    np.testing.assert_array_equal(mixed.completing[rows], alone.completing[rows])
    assert mixed.ok.dtype == bool and mixed.completing.dtype == bool
    if rule != "commit_guard":
        default = check_candidate(*args, PRM)
        assert (default.ok[rows] != alone.ok[rows]).any() or (default.completing[rows] != alone.completing[rows]).any()


def test_with_l0_a_rule_with_a_higher_level_completes_only_at_that_level():
    """With L0, the step completes at the higher of the own-lane level and the completion rule's own level
    (``paper_body_across``: half a vehicle width past the boundary): a step ending between the two does not complete."""
    rule = COMPLETION_RULES["paper_body_across"]
    y_end = 0.5 * (own_completion_level(PRM) + rule.level(PRM))
    assert own_completion_level(PRM) < y_end < rule.level(PRM)
    n = 1
    far = np.full(n, FAR)
    args = (np.zeros(n), np.full(n, y_end - 0.05), np.full(n, 20.0), np.full(n, 0.5), np.zeros(n), np.zeros(n), far,
            np.full(n, 30.0), np.zeros(n), -far, np.zeros(n), np.zeros(n, bool))  # fmt: skip
    own = (np.full(n, 300.0), np.full(n, 20.0), np.full(n, PRM.a_x_d))
    assert not check_candidate(*args, PRM, completion=rule, own=own).completing[0]
    assert check_candidate(*args, PRM, own=own).completing[0]  # the default rule's level is below y_end


def test_the_uncompiled_switch_keeps_the_own_lane_rows_on_numpy(monkeypatch):
    """``SAFELANE_NO_NUMBA=1`` (debugging, mutation testing) keeps the rows with L0 on the NumPy functions: no kernel
    module is handed out."""
    from safelane.shield import decide

    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    assert decide.own_kernel() is None
