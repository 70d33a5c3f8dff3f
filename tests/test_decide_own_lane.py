"""The shield's decision with a leader L0 in the ego's own lane (``check_candidate(..., own=...)``, issue 17).

The reference is independent of the library: with L1 and F far away, a proposal is safe iff (1) the ego's gap to L0
braking at its worst case stays >= p_m during the period (exact minimum of a quadratic), and (2) from the period's
end the ego can keep p_m behind L0 by braking at a_x_d — checked here by time stepping both vehicles to a stop on a
fine grid (braking to rest and following L0 have the same minimum gap: they coincide until the speeds meet).
"""

from __future__ import annotations

import numpy as np

from safelane import Params
from safelane.safety.longitudinal import FEASIBILITY_TOL_M
from safelane.shield.decide import check_candidate, own_completion_level

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
