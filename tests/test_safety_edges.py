"""The safety engine exactly on its boundaries, and the contract around its values.

Boundaries: the tolerance band of a chain link at its margin, a link that needs exactly ``a_x_d``, the case boundary
of Eq. 2, a lateral return that just stops at ``y_s``, an intrusion of exactly ``LATERAL_TOL_M``, a parked ``L1`` that
never brakes, the Figure-3 case labels where braking ends or ``L1`` stops exactly at ``T``, the feasibility tolerance
(inclusive). Contract: NumPy scalars for scalar input, the batch taken from any argument, cached arguments that may
be left out, no floating-point warnings even at extreme (finite) inputs, no division by zero in the NumPy backend,
error messages that quote the offending value.

Random data (``test_safety_reference.py``, ``test_safety_shapes.py``) almost never lands exactly on a boundary, so
each is pinned here by hand, on both backends (Python floats and NumPy arrays). ``GOLDEN`` is the round-number
parameter set of ``test_safety_golden.py`` (``a_x_a = 2``, ``a_x_d = 8``, ``a_y_m = 2`` m/s², ``y_s = 1``,
``p_m = 5``, ``p_m_human = 10`` m).
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

import scenarios
from safelane import Params
from safelane.safety import (
    Reason,
    evasion_exists,
    lateral_evasion_time,
    leader_chain,
    leader_position,
    longitudinal_evasion,
    plan_evasion,
    worst_case_leader_decel,
)
from safelane.safety._backend import ARRAY, FEASIBILITY_TOL_M, SCALAR
from safelane.safety._checks import bool_array
from safelane.safety.chain import braked_position, min_follow_decel
from safelane.safety.lateral import LATERAL_TOL_M
from safelane.safety.longitudinal import leader_gap_min, longitudinal_core
from test_safety_golden import DEFAULT, GOLDEN  # the golden cases' parameters

BACKENDS = pytest.mark.parametrize("xp", [SCALAR, ARRAY], ids=["scalar", "array"])


def _z(xp, slack, v_f, v_l, a_l) -> float:
    """``min_follow_decel`` on one backend, as a float (the NumPy path takes 1-element arrays)."""
    if xp is SCALAR:
        return float(min_follow_decel(SCALAR, float(slack), float(v_f), float(v_l), float(a_l)))
    args = (np.array([float(x)]) for x in (slack, v_f, v_l, a_l))
    return float(min_follow_decel(ARRAY, *args)[0])


# --- a chain link at its margin: the tolerance band of min_follow_decel ----------------------------------------------


@BACKENDS
def test_a_link_one_nanometre_inside_its_margin_counts_as_at_it(xp):
    # slack = −FEASIBILITY_TOL_M is the edge of the band: taken as max(−1 nm + 0.5 nm, 0) = 0, at the margin. At equal
    # speeds (20 m/s) behind a leader braking at 8 the follower must brake like it: z = 400 / (2·0 + 400/8) = 8.
    assert _z(xp, -FEASIBILITY_TOL_M, 20.0, 20.0, 8.0) == 8.0
    # Both at rest there: nothing to do (z = 0; the stopping distances and the slack are all zero).
    assert _z(xp, -FEASIBILITY_TOL_M, 0.0, 0.0, 8.0) == 0.0
    # Closing there (1 m/s faster): the equal-speed case with zero room, which no finite deceleration achieves.
    assert _z(xp, -FEASIBILITY_TOL_M, 21.0, 20.0, 8.0) == np.inf
    # Beyond the band (1.5 nm inside): inside the margin, whatever the speeds.
    for v_f, v_l in ((20.0, 20.0), (0.0, 0.0)):
        assert _z(xp, -1.5 * FEASIBILITY_TOL_M, v_f, v_l, 8.0) == np.inf


@BACKENDS
def test_a_slack_of_half_the_tolerance_gains_the_other_half(xp):
    # slack = 0.5 nm (the top of the shifted band) is taken as 0.5 + 0.5 = 1 nm. A follower at 1 mm/s behind a
    # leader at rest (braking at 8, so not the equal-speed case: 2·1e-9·8 > 0·1e-3): z = v_f² / (2 slack)
    # = 1e-6 / 2e-9 = 500 (with the unshifted 0.5 nm it would be 1000).
    assert _z(xp, 0.5 * FEASIBILITY_TOL_M, 1e-3, 0.0, 8.0) == pytest.approx(500.0, rel=1e-12)
    # Just above it the slack is its own: 0.6 nm gives 1e-6 / 1.2e-9.
    assert _z(xp, 0.6 * FEASIBILITY_TOL_M, 1e-3, 0.0, 8.0) == pytest.approx(1e-6 / 1.2e-9, rel=1e-12)


@BACKENDS
def test_a_slow_leader_that_never_brakes_needs_nothing_from_a_slower_follower(xp):
    # L2 at a constant 0.8 m/s (a_l = 0: it never stops) and L1 at 0.5 m/s, 10 m beyond the margin: the gap only
    # grows, z = 0. (Below 1 m/s, so a stopping distance taken as 0 instead of infinite would show: z = 0.25/20.)
    assert _z(xp, 10.0, 0.5, 0.8, 0.0) == 0.0
    assert _z(xp, 10.0, 0.8, 0.8, 0.0) == 0.0
    # A faster follower closes on it: the equal-speed case, z = 0 + 0.3² / (2·10).
    assert _z(xp, 10.0, 1.1, 0.8, 0.0) == pytest.approx(0.09 / 20.0, rel=1e-12)


def test_min_follow_decel_on_the_case_boundary_is_the_same_on_both_backends():
    # On the boundary between the cases (2·slack·a_l = v_l·Δv) both formulas equal a_l·v_f/v_l; the two backends
    # pick the same one (the equal-speed case, `<=`), bit for bit. These slacks make the two formulas round apart.
    rng = np.random.default_rng(5)
    v_l = rng.uniform(1.0, 30.0, 4000)
    v_f = v_l + rng.uniform(0.1, 10.0, 4000)
    a_l = rng.uniform(0.5, 8.0, 4000)
    dv = v_f - v_l
    slack = v_l * dv / (2.0 * a_l)
    on_boundary = 2.0 * slack * a_l == v_l * dv
    z_a = a_l + dv * dv / (2.0 * slack)
    z_b = v_f * v_f / (2.0 * slack + v_l * v_l / a_l)
    pick = on_boundary & (z_a != z_b)
    assert pick.sum() > 10
    args = [x[pick] for x in (slack, v_f, v_l, a_l)]
    batched = min_follow_decel(ARRAY, *args)
    np.testing.assert_array_equal(batched, z_a[pick])
    np.testing.assert_array_equal([min_follow_decel(SCALAR, *map(float, row)) for row in zip(*args, strict=True)],
                                  z_a[pick])  # fmt: skip


def test_min_follow_decel_numpy_path_raises_no_floating_point_warnings():
    # The NumPy path divides raw (by a_l = 0, by a zero slack) and masks afterwards, under its own errstate: a
    # direct caller (the simulator's scans, safety.responsible) sees no warning.
    slack = np.array([0.0, -1e-9, 10.0, 5.0, -3.0])
    v_f = np.array([0.0, 20.0, 5.0, 0.0, 4.0])
    v_l = np.array([0.0, 20.0, 3.0, 0.0, 0.0])
    a_l = np.array([0.0, 8.0, 0.0, 0.0, 8.0])
    with warnings.catch_warnings(), np.errstate(all="warn"):
        warnings.simplefilter("error")
        z = min_follow_decel(ARRAY, slack, v_f, v_l, a_l)
    assert z.tolist() == [0.0, 8.0, 0.2, 0.0, np.inf]  # the third closes: 0 + 2²/(2·10)


# --- the chain on its boundaries --------------------------------------------------------------------------------------


@pytest.mark.parametrize("batched", [False, True])
def test_a_link_that_needs_exactly_the_mechanical_limit_is_safe(batched):
    # L1 20 m/s, L2 (unconnected, a_x_d = 8) 10 m/s, slack 23.75 − 5 = 18.75: L2 stops first (2·18.75·8 = 300 >
    # 10·10), z = 400/(2·18.75 + 100/8) = 400/50 = 8 = a_x_d exactly: L1 can still keep p_m, the chain is safe.
    p, v = [0.0, 23.75], [20.0, 10.0]
    if batched:
        p, v = np.array([p, p]), np.array([v, v])
    result = leader_chain(p, v, np.zeros((2, 1)) if batched else [0.0], GOLDEN)
    assert np.all(result.required[..., 0] == 8.0)
    assert not np.any(result.unsafe)
    assert np.all(result.l1_decel == 8.0)


def test_the_batch_may_come_from_the_promises_or_the_human_flags_alone():
    # One chain's positions and speeds, four promise vectors (or four human-driven patterns): four chains, each as
    # if evaluated alone.
    p, v = [0.0, 30.0, 60.0], [25.0, 22.0, 25.0]
    promises = np.array([[0.0, 0.0], [2.0, 1.0], [6.0, 6.0], [8.0, 3.0]])
    humans = np.array([[False, False], [True, False], [False, True], [True, True]])
    by_promise = leader_chain(p, v, promises, DEFAULT, human_driven=[False, True])
    by_human = leader_chain(p, v, [1.0, 1.0], DEFAULT, human_driven=humans)
    assert by_promise.decel.shape == by_human.decel.shape == (4, 3)
    assert by_promise.unsafe.shape == by_human.unsafe.shape == (4,)
    for i in range(4):
        one = leader_chain(p, v, promises[i], DEFAULT, human_driven=[False, True])
        np.testing.assert_array_equal(by_promise.decel[i], one.decel)
        np.testing.assert_array_equal(by_promise.required[i], one.required)
        assert by_promise.l1_decel[i] == one.l1_decel
        one = leader_chain(p, v, [1.0, 1.0], DEFAULT, human_driven=humans[i])
        np.testing.assert_array_equal(by_human.decel[i], one.decel)
        assert by_human.unsafe[i] == one.unsafe and by_human.l1_decel[i] == one.l1_decel
    assert len(set(by_promise.l1_decel.tolist())) > 1 and len(set(by_human.decel[:, 0].tolist())) > 1


# --- the lateral return on its boundary -------------------------------------------------------------------------------


@pytest.mark.parametrize("batched", [False, True])
def test_returning_at_exactly_the_speed_that_stops_at_y_s(batched):
    # e = 2 − 1 = 1 beyond y_s, returning at 2 m/s: braking the return at a_y_m = 2 stops it exactly at y_s
    # (s = 1 − 4/4 = 0), at t = 2/2 = 1 s; the returning-fast root (2 − sqrt(4 − 4))/2 = 1, no switch.
    p_y, v_y = (np.array([2.0]), np.array([-2.0])) if batched else (2.0, -2.0)
    t_y_f, t_switch = lateral_evasion_time(p_y, v_y, GOLDEN)
    assert np.all(t_y_f == 1.0) and np.all(t_switch == 0.0)


def test_returning_at_the_stopping_speed_has_no_first_phase():
    # The same state in a plan: the return brakes its lateral speed at +a_y_m from t = 0 (no −a_y_m phase, s = 0 is
    # not the bang-bang case) and ends at rest on y_s at t = 1.
    plan = plan_evasion(0.0, 2.0, 20.0, -2.0, 100.0, 20.0, 0.0, -100.0, 20.0, False, GOLDEN)
    assert plan.t_y_f == 1.0 and plan.t_y_switch == 0.0
    assert plan.y_acc_1 == 0.0 and plan.y_acc_2 == 2.0 and plan.t_y_end == 1.0
    _, py, _, vy = plan.state(1.0)
    assert py == 1.0 and vy == 0.0


#: A lane 2⁻³⁰ m (0.93 nm) wider than the car: y_s = 2⁻³¹ m, small enough that an intrusion of exactly
#: LATERAL_TOL_M (1 nm) is representable as p_y − y_s (with y_s = 1 m it is not: p_y − 1 is a multiple of 2⁻⁵²).
NARROW = Params(a_x_a=2.0, a_x_d=8.0, a_y_m=2.0, lane_width=1.0 + 2.0**-30, vehicle_width=1.0, vehicle_length=4.5,
                p_m=5.0, p_m_human=10.0)  # fmt: skip


@pytest.mark.parametrize("batched", [False, True])
def test_an_intrusion_of_exactly_the_lateral_tolerance_counts_as_none(batched):
    y_s = NARROW.y_safe
    # At rest exactly LATERAL_TOL_M beyond y_s: nothing to evade (the band's edge is inside it) ...
    at_rest = (y_s + LATERAL_TOL_M, 0.0)
    # ... and drifting out at 2⁻²⁰ m/s from LATERAL_TOL_M − 2⁻⁴² m beyond y_s: full lateral braking stops it after
    # (2⁻²⁰)²/(2·2) = 2⁻⁴² m, exactly LATERAL_TOL_M beyond y_s (s = LATERAL_TOL_M): nothing to evade either.
    drifting = (y_s + (LATERAL_TOL_M - 2.0**-42), 2.0**-20)
    assert at_rest[0] - y_s == LATERAL_TOL_M
    assert (drifting[0] - y_s) + drifting[1] ** 2 / (2.0 * NARROW.a_y_m) == LATERAL_TOL_M
    for p_y, v_y in (at_rest, drifting):
        if batched:
            p_y, v_y = np.array([p_y]), np.array([v_y])
        assert np.all(lateral_evasion_time(p_y, v_y, NARROW)[0] == 0.0)
    # One step further out, there is: a bang-bang return of a few tens of microseconds.
    assert lateral_evasion_time(np.nextafter(at_rest[0], 1.0), 0.0, NARROW)[0] > 0.0
    assert lateral_evasion_time(drifting[0], 1.001 * drifting[1], NARROW)[0] > 0.0


@pytest.mark.parametrize(
    ("p_y", "v_y", "acc", "t_rest", "y_rest"),
    [
        # Inside its lane drifting out at 1 m/s (stops at 0.75 <= y_s): it brakes the drift at −a_y_m for 0.5 s.
        (0.5, 1.0, -2.0, 0.5, 0.75),
        # Inside, moving home at 0.3 m/s: it brakes the return at +a_y_m for 0.15 s, 0.045 − 0.0225 m further in.
        (0.5, -0.3, 2.0, 0.15, 0.4775),
    ],
)
def test_with_nothing_to_evade_the_plan_brakes_the_lateral_speed_to_rest(p_y, v_y, acc, t_rest, y_rest):
    plan = plan_evasion(0.0, p_y, 20.0, v_y, 100.0, 20.0, 0.0, -100.0, 20.0, False, GOLDEN)
    assert plan.t_y_f == 0.0 and plan.reason & Reason.NOTHING_TO_EVADE
    assert plan.y_acc_2 == acc and plan.t_y_end == pytest.approx(t_rest, rel=1e-12)
    _, py, _, vy = plan.state(np.array([0.5 * t_rest, t_rest, 10.0]))
    assert vy[0] == pytest.approx(v_y + acc * 0.5 * t_rest, rel=1e-12)
    assert py[1:] == pytest.approx([y_rest, y_rest], rel=1e-12) and vy[1:] == pytest.approx([0.0, 0.0], abs=1e-15)


def test_inside_the_lateral_tolerance_the_plan_still_ends_at_lateral_rest():
    # At rest exactly LATERAL_TOL_M beyond y_s (nothing to evade, see above): whatever the plan does laterally within
    # the band, it comes back to rest there (no lateral drift afterwards).
    plan = plan_evasion(0.0, NARROW.y_safe + LATERAL_TOL_M, 20.0, 0.0, 100.0, 20.0, 0.0, -100.0, 20.0, False, NARROW)
    assert plan.t_y_f == 0.0
    _, py, _, vy = plan.state(np.array([1.0, 1e3]))
    assert np.all(vy == 0.0) and np.all(np.abs(py - NARROW.y_safe) <= LATERAL_TOL_M)


# --- the longitudinal profile behind a parked L1 that never brakes ----------------------------------------------------


@pytest.mark.parametrize("batched", [False, True])
def test_parked_l1_with_zero_deceleration_is_case_2(batched):
    # L1 parked (v = 0, decel = 0) at 6.8125 m; ego at 2 m/s, T = 2. u = 0.5: V = 3, brakes 3/8 s over 9/16 m and
    # rests at 1 + 0.25 + 0.5625 = 1.8125 m at t = 0.875 s, exactly p_m behind L1. L1 never moves: the ego stops,
    # it does not "follow" (case 2, not 3 or 4). Eq. 7 second case: −1 + sqrt(1 − (4 + 16·(5 − 6.8125))/20) = 0.5.
    args = (0.0, 2.0, 6.8125, 0.0, 0.0, 2.0)
    if batched:
        args = tuple(np.array([x]) for x in args)
    result = longitudinal_evasion(*args, GOLDEN)
    assert np.all(result.case == 2)
    assert np.all(result.t_x1 == pytest.approx(0.5, rel=1e-12))
    assert np.all(result.t_x2 == pytest.approx(0.875, rel=1e-12))
    assert np.all(result.min_gap == pytest.approx(5.0, rel=1e-12))
    plan = plan_evasion(0.0, 3.0, 2.0, 0.0, 6.8125, 0.0, 0.0, -100.0, 0.0, False, GOLDEN)  # T = 2 (at rest, e = 2)
    assert plan.t_y_f == 2.0 and not plan.follows_leader


def test_behind_a_parked_l1_that_never_brakes_both_backends_agree_bit_for_bit():
    # L1 at rest with decel 0 (stopping distance 0, stop time 0): the two backends evaluate the same closed forms in
    # the same IEEE arithmetic, so they agree exactly, not just to the 1e-12 of the general parity test.
    rng = np.random.default_rng(1)
    n = 300
    v, p1, T = rng.uniform(0.0, 35.0, n), rng.uniform(DEFAULT.p_m - 1.0, 80.0, n), rng.uniform(0.0, 6.0, n)
    zero = np.zeros(n)
    batched = longitudinal_evasion(zero, v, p1, zero, zero, T, DEFAULT)
    assert 0 < batched.feasible.sum() < n
    for i in range(n):
        one = longitudinal_evasion(0.0, v[i].item(), p1[i].item(), 0.0, 0.0, T[i].item(), DEFAULT)
        for field in ("feasible", "t_x1", "t_x2", "case", "min_gap"):
            assert getattr(one, field) == getattr(batched, field)[i], (field, i)


@pytest.mark.parametrize("batched", [False, True])
def test_case_labels_on_their_boundaries(batched):
    # Figure-3 case 2 of test_safety_golden with T = 2.25, the instant the ego comes to rest (u = 1 still: the gap
    # binds at rest): braking ends exactly at T, which counts as still braking at T (case 1).
    # Case 4 there with T = 3, the instant L1 (12 m/s at 4) comes to rest: followed to a stop not *before* T (case 3).
    # Ego at 11 m/s behind L1 (11.75 m, 8 m/s braking at 4, at rest at t = 2), T = 3: u = 0.5 brings the ego (12 m/s
    # at u, then braking at 8) to rest at t = 2 too, 5.5 + 0.25 + 9 = 14.75 m, exactly p_m behind L1's 19.75 m:
    # the speeds meet (at 0) as L1 stops, which counts as following it to a stop (case 4, not 2).
    cases = (((0.0, 8.0, 19.25, 4.0, 8.0, 2.25), 1, 2.25), ((0.0, 12.0, 12.5, 12.0, 4.0, 3.0), 3, 2.5),
             ((0.0, 11.0, 11.75, 8.0, 4.0, 3.0), 4, 2.0))  # fmt: skip
    for args, case, t_x2 in cases:
        if batched:
            args = tuple(np.array([x]) for x in args)
        result = longitudinal_evasion(*args, GOLDEN)
        assert np.all(result.case == case)
        assert np.all(result.t_x2 == t_x2) and np.all(result.min_gap == 5.0)
        assert np.all(result.t_x1 == (0.5 if case == 4 else 1.0))


@BACKENDS
def test_leader_gap_min_computes_its_cached_arguments_when_not_given(xp):
    # l1_stop and l1_at_T are caches (longitudinal_core passes them once for all candidates): without them the
    # minimum gap is the same, computed from L1's state.
    rng = np.random.default_rng(7)
    for _ in range(40):
        p, v, v1, a1 = 0.0, rng.uniform(0, 30), rng.uniform(0, 30), rng.choice([0.0, rng.uniform(0, 8), 8.0])
        p1, T = rng.uniform(5, 60), rng.uniform(0.1, 5)
        u = rng.uniform(0, T)
        if xp is ARRAY:
            p, v, p1, v1, a1, T, u = (np.array([x]) for x in (p, v, p1, v1, a1, T, u))
        d0 = p1 - p - DEFAULT.p_m
        l1_stop = xp.stop_time(v1, a1)
        l1_at_T = braked_position(xp, p1, v1, a1, T, l1_stop)
        given = leader_gap_min(xp, u, T, d0, p, v, p1, v1, a1, DEFAULT.p_m, DEFAULT, l1_stop, l1_at_T)
        assert leader_gap_min(xp, u, T, d0, p, v, p1, v1, a1, DEFAULT.p_m, DEFAULT) == given
        assert leader_gap_min(xp, u, T, d0, p, v, p1, v1, a1, DEFAULT.p_m, DEFAULT, l1_stop=l1_stop) == given
        assert leader_gap_min(xp, u, T, d0, p, v, p1, v1, a1, DEFAULT.p_m, DEFAULT, l1_at_T=l1_at_T) == given


@BACKENDS
def test_the_feasibility_tolerance_is_inclusive(xp):
    # longitudinal_core keeps gaps down to −tol. With tol = 0 a gap of exactly 0 (to the margin) is kept:
    # * L1 parked exactly p_m ahead of an ego at rest: feasible (braking from t = 0 keeps the gap at 0), t_x1 = 0;
    # * Figure-3 case 1 of test_safety_golden (the gap at T is exactly p_m for u = 1): u = 1 is taken.
    def core(p, v, p1, v1, a1, T):
        args = (p, v, p1, v1, a1, T) if xp is SCALAR else tuple(np.array([x]) for x in (p, v, p1, v1, a1, T))
        feasible, u, *_, gap = longitudinal_core(xp, *args, GOLDEN.p_m, GOLDEN, tol=0.0)
        return bool(np.all(feasible)), float(np.asarray(u).ravel()[0]), float(np.asarray(gap).ravel()[0])

    assert core(0.0, 0.0, 5.0, 0.0, 0.0, 1.0) == (True, 0.0, 0.0)
    assert core(0.0, 20.0, 12.0, 20.0, 4.0, 2.0) == (True, 1.0, 0.0)


@BACKENDS
def test_the_default_tolerance_keeps_gaps_down_to_minus_one_nanometre(xp):
    # With the default tol (FEASIBILITY_TOL_M, 1 nm): an ego exactly at the margin behind L1, both at the same speed
    # and braking alike, keeps a gap of exactly 0 (feasible); 0.5 nm inside the margin is still kept, 2 nm is not.
    def feasible(inside_m, v):
        args = (0.0, v, DEFAULT.p_m - inside_m, v, DEFAULT.a_x_d, 1.0)
        args = args if xp is SCALAR else tuple(np.array([x]) for x in args)
        ok, *_ = longitudinal_core(xp, *args, DEFAULT.p_m, DEFAULT)
        return bool(np.all(ok))

    for v in (0.0, 20.0):
        assert feasible(0.0, v) and feasible(0.5 * FEASIBILITY_TOL_M, v)
        assert not feasible(2.0 * FEASIBILITY_TOL_M, v)


def test_a_batch_whose_horizons_are_all_equal_is_solved_in_full():
    # Every row with t_y_f = 1 s (not 0: no shortcut applies) gets the optimum its scalar evaluation gets.
    rng = np.random.default_rng(4)
    n = 50
    args = (np.zeros(n), rng.uniform(0, 30, n), rng.uniform(6.0, 40.0, n), rng.uniform(0, 30, n), rng.uniform(0, 8, n),
            np.ones(n))  # fmt: skip
    batched = longitudinal_evasion(*args, GOLDEN)
    assert (batched.t_x1 > 0.0).sum() > n // 2
    for i in range(n):
        one = longitudinal_evasion(*(a[i].item() for a in args), GOLDEN)
        assert (one.t_x1, one.case, one.feasible) == (batched.t_x1[i], batched.case[i], batched.feasible[i])


# --- NumPy scalars for scalar input -----------------------------------------------------------------------------------


def test_scalar_inputs_give_numpy_scalars_everywhere():
    assert type(leader_position(40.0, 25.0, 8.0, 1.0, DEFAULT)) is np.float64
    for value in lateral_evasion_time(1.5, 0.3, DEFAULT):
        assert type(value) is np.float64
    lon = longitudinal_evasion(0.0, 25.0, 40.0, 25.0, 8.0, 2.0, DEFAULT)
    kinds = dict(feasible=np.bool_, t_x1=np.float64, t_x2=np.float64, case=np.int8, min_gap=np.float64)
    for field, kind in kinds.items():
        assert type(getattr(lon, field)) is kind, field
    chain = leader_chain([0.0, 30.0, 60.0], [25.0, 25.0, 25.0], [2.0, 2.0], DEFAULT)
    assert type(chain.unsafe) is np.bool_ and type(chain.l1_decel) is np.float64
    assert type(worst_case_leader_decel([0.0, 30.0], [25.0, 25.0], [2.0], DEFAULT)) is np.float64
    plan = plan_evasion(**scenarios.open_gap_collaborative_follower(), params=DEFAULT)
    assert type(plan.feasible) is np.bool_ and type(plan.follows_leader) is np.bool_
    for field in ("t_y_f", "t_x1", "t_x2", "min_gap_leader", "min_gap_follower", "ego_px", "l1_decel", "v_switch"):
        assert type(getattr(plan, field)) is np.float64, field


# --- no floating-point warnings, even at extreme finite inputs --------------------------------------------------------


def test_extreme_finite_inputs_raise_no_floating_point_warnings():
    # Finite inputs near the top of the float range overflow inside the closed forms (v², p + v t): every public
    # function evaluates under its own errstate, so the caller gets inf/nan values, never a RuntimeWarning.
    big = np.array([1e300, 1e200, 10.0])
    with warnings.catch_warnings(), np.errstate(all="warn"):
        warnings.simplefilter("error")
        leader_position(big, big, 0.0, big, DEFAULT)
        leader_position(1e300, 1e300, 0.0, 1e300, DEFAULT)
        lateral_evasion_time(big, big, DEFAULT)
        lateral_evasion_time(1e300, 1e300, DEFAULT)
        longitudinal_evasion(-big, big, big, big, 0.0, big, DEFAULT)
        leader_chain(np.array([[-1e308, 1e308], [0.0, 30.0]]), np.full((2, 2), 1e200), np.ones((2, 1)), DEFAULT)
        leader_chain([-1e308, 1e308], [1e200, 1e200], [1.0], DEFAULT)
        plan = plan_evasion(**{**scenarios.open_gap_collaborative_follower(), "ego_px": np.zeros(2)}, params=DEFAULT)
        plan.state(np.array([1e308, 1e200]))  # beyond t_y_f it holds its speed: v·t overflows


def test_the_numpy_backend_never_divides_by_zero():
    # div, stop_dist and stop_time guard their divisors before dividing (the module's promise): zero divisors give
    # the fallback without a floating-point warning, even outside the callers' errstate.
    zero, v = np.zeros(3), np.array([0.0, 2.0, 3.0])
    with warnings.catch_warnings(), np.errstate(all="warn"):
        warnings.simplefilter("error")
        assert ARRAY.div(v, zero, 7.0).tolist() == [7.0, 7.0, 7.0]
        assert ARRAY.stop_dist(v, zero).tolist() == [0.0, np.inf, np.inf]
        assert ARRAY.stop_time(v, zero).tolist() == [0.0, np.inf, np.inf]
        assert ARRAY.div(v, np.array([1.0, 4.0, 0.0]), 7.0).tolist() == [0.0, 0.5, 7.0]


def test_flags_given_as_numbers_become_booleans():
    flags = bool_array("flag", [0, 1, 1.0, 0.0])
    assert flags.dtype == np.bool_ and flags.tolist() == [False, True, True, False]


# --- error messages quote the offending value -------------------------------------------------------------------------

NAN = r"(np\.float64\()?nan\)?"


def test_a_bad_scalar_among_arrays_is_quoted_without_an_index():
    # A scalar argument in a batched call: its value, and no index (it has none).
    state = {**scenarios.open_gap_collaborative_follower(), "ego_px": np.zeros(3), "ego_py": np.nan}
    with pytest.raises(ValueError) as info:
        evasion_exists(**state, params=DEFAULT)
    assert re.fullmatch(rf"ego_py must be finite; got {NAN}", str(info.value)), str(info.value)


def test_a_bad_array_entry_is_quoted_with_its_index():
    state = {**scenarios.open_gap_collaborative_follower(), "ego_py": np.array([1.0, 1.0, np.nan, 1.0])}
    with pytest.raises(ValueError) as info:
        evasion_exists(**state, params=DEFAULT)
    assert re.fullmatch(rf"ego_py must be finite; got {NAN} at index \(2,\)", str(info.value)), str(info.value)


def test_shapes_that_do_not_broadcast_are_listed():
    with pytest.raises(ValueError) as info:
        lateral_evasion_time(np.zeros(3), np.zeros(4), DEFAULT)
    assert str(info.value) == "input shapes do not broadcast together: p_y(3,), v_y(4,)"


def test_an_out_of_range_promise_is_quoted():
    # The first promise outside [0, a_x_d]; 0, a_x_d itself and 0.5 are inside.
    p, v = [0.0, 20.0, 40.0, 60.0, 80.0], [20.0] * 5
    with pytest.raises(ValueError) as info:
        leader_chain(p, v, [0.0, 8.0, 0.5, -0.1], DEFAULT)
    assert re.search(r"got (np\.float64\()?-0\.1\)?$", str(info.value)), str(info.value)


@pytest.mark.parametrize("speed", [1e160, 1e200, 1e300])
def test_huge_finite_inputs_give_the_same_results_on_both_backends_without_an_overflow_error(speed):
    """Finite but absurd speeds and positions (validated finite, so accepted): the pure-Python backend used to raise
    ``OverflowError`` from ``(v / a_a) ** 2`` beyond ~1e154 m/s, where NumPy's arithmetic gives ``inf``. Both backends
    now run the same float arithmetic: the scalar call returns what the array call returns."""
    args = (0.0, speed, 10.0 * speed, 1.0, 0.0, 1.0)
    scalar = longitudinal_evasion(*args, DEFAULT)
    batched = longitudinal_evasion(*(np.array([a]) for a in args), DEFAULT)
    for field in ("feasible", "t_x1", "t_x2", "case", "min_gap"):
        np.testing.assert_array_equal(np.asarray(getattr(scalar, field)).reshape(1), getattr(batched, field), field)
    ok = evasion_exists(0.0, 0.0, speed, 0.0, 10.0 * speed, 1.0, 0.0, -10.0, 0.0, False, DEFAULT)
    ok_b = evasion_exists(*(np.array([a]) for a in (0.0, 0.0, speed, 0.0, 10.0 * speed, 1.0, 0.0, -10.0, 0.0)),
                          np.array([False]), DEFAULT)  # fmt: skip
    assert bool(ok) == bool(ok_b[0])
