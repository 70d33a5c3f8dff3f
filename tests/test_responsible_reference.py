"""``safelane.safety.responsible`` against an independent, exact time-stepped reference (``tests/reference.py``'s
piecewise-constant integration and exact gap minimum; nothing imported from ``safelane.safety`` for the reference):
the gap minimum over one period (:func:`pair_min_gap`), the full responsible check (:func:`responsible_ok`, with a
softer ``brake`` and a tolerance), the closed-form bound for any ``brake >= lead_decel`` (bisection on the
reference), the final stop with a softer ``brake``, and :func:`responsible_accel`'s cap and floor.
Seeded, a few hundred rows: fast."""

from __future__ import annotations

import numpy as np
import pytest

from reference import gap_minimum, integrate, midpoints, time_nodes
from safelane import Params
from safelane.safety.responsible import (
    ROOT_EPS_MPS2,
    final_stop_accel,
    pair_min_gap,
    responsible_accel,
    responsible_bound,
    responsible_bounds,
    responsible_ok,
)

PRM = Params()


def _stop(v, a):
    """When a vehicle at ``v >= 0`` accelerating at ``a`` comes to rest (``inf`` if it does not brake)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a < 0.0, np.where(v > 0.0, v / np.where(a < 0.0, -a, 1.0), 0.0), np.inf)


def ref_pair_gap(slack, v_f, a_f, v_l, a_l, horizon, a_f_after=None, switch=None):
    """Exact minimum over ``[0, horizon]`` of ``slack + x_l(t) − x_f(t)``: the leader at constant ``a_l``, the
    follower at ``a_f`` (until ``switch``, then ``a_f_after``), each stopping at rest, by time stepping on nodes
    that include every event (the integration of ``tests/reference.py``)."""
    slack, v_f, a_f, v_l, a_l, horizon = (np.asarray(x, float) for x in np.broadcast_arrays(slack, v_f, a_f, v_l, a_l,
                                                                                               horizon))  # fmt: skip
    if switch is None:
        switch, a_f_after = horizon, a_f
    switch = np.broadcast_to(np.asarray(switch, float), slack.shape)
    a_f_after = np.broadcast_to(np.asarray(a_f_after, float), slack.shape)
    # The follower's state at the switch (for its second stop), the events, then the integration.
    w = np.maximum(v_f + a_f * switch, 0.0)
    stop_f1 = _stop(v_f, a_f)
    stop_f2 = switch + _stop(w, a_f_after)
    stop_l = _stop(v_l, a_l)
    events = [np.where(np.isfinite(e), e, 0.0) for e in (stop_f1, stop_f2, stop_l, switch)]
    nodes = time_nodes(horizon, events, 65)
    mid = midpoints(nodes)
    acc_f = np.where(mid < switch[:, None], a_f[:, None], a_f_after[:, None])
    acc_f = np.where((mid < switch[:, None]) & (mid >= stop_f1[:, None]), 0.0, acc_f)
    acc_f = np.where((mid >= switch[:, None]) & (mid >= stop_f2[:, None]), 0.0, acc_f)
    acc_l = np.where(mid < stop_l[:, None], a_l[:, None], 0.0)
    pf, vf = integrate(nodes, np.zeros(slack.shape), v_f, acc_f)
    pl, vl = integrate(nodes, slack, v_l, acc_l)
    g, _ = gap_minimum(nodes, pl, vl, acc_l, pf, vf, acc_f)
    return g


def ref_ok(a, slack, v_f, v_l, lead_decel, brake, dt=PRM.dt):
    """Minimum gap beyond the margin when the follower takes ``a`` for ``dt`` then brakes at ``brake`` to rest,
    the leader braking at ``lead_decel`` to rest: over a horizon past both stops."""
    horizon = dt + (v_f + np.abs(a) * dt) / brake + np.where(lead_decel > 0.0, v_l / np.maximum(lead_decel, 1e-12),
                                                            0.0) + 1.0  # fmt: skip
    return ref_pair_gap(slack, v_f, a, v_l, -lead_decel, horizon, a_f_after=-brake, switch=dt)


def _rows(rng, n):
    slack = np.where(rng.random(n) < 0.5, rng.uniform(0.0, 3.0, n), rng.uniform(-1.0, 30.0, n))
    v_f = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.0, 35.0, n))
    v_l = np.where(rng.random(n) < 0.1, 0.0, np.clip(v_f + rng.normal(0.0, 5.0, n), 0.0, None))
    return slack, v_f, v_l


@pytest.mark.parametrize("seed", range(3))
def test_pair_min_gap_is_the_exact_minimum_over_the_period(seed):
    """Both vehicles at any constant acceleration (braking to rest inside the period, accelerating from rest,
    equal accelerations, equal speeds), over periods of 0.1 and 0.3 s."""
    rng = np.random.default_rng(seed)
    n = 600
    slack, v_f, v_l = _rows(rng, n)
    slack = np.where(rng.random(n) < 0.1, 0.0, slack)
    a_f = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(-10.0, 4.0, n))
    a_l = np.where(rng.random(n) < 0.1, a_f, rng.uniform(-10.0, 4.0, n))
    v_l = np.where(rng.random(n) < 0.1, v_f, v_l)
    v_f[::13] = 0.05  # stops early in the period when braking
    for dt in (0.1, 0.3):
        got = pair_min_gap(slack, v_f, a_f, v_l, a_l, dt)
        want = ref_pair_gap(slack, v_f, a_f, v_l, a_l, np.full(n, dt))
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
        assert (got < slack - 1e-3).sum() > 50 and (got == slack).sum() > 20
    # The interior minimum (equal speeds) is what binds in some rows: not at 0 nor at the end of the period.
    end = slack + v_l * 0.1 + 0.5 * a_l * 0.01 - v_f * 0.1 - 0.5 * a_f * 0.01
    inner = (np.minimum(slack, end) - pair_min_gap(slack, v_f, a_f, v_l, a_l, 0.1)) > 1e-6
    assert inner.sum() >= 3


@pytest.mark.parametrize("seed", range(2))
def test_responsible_ok_is_the_exact_check_with_any_brake_and_tolerance(seed):
    """``responsible_ok(a, ..., brake)`` is "the minimum gap (``a`` for one period, then braking at ``brake``
    against the leader braking at ``lead_decel``) keeps the margin", on rows clear of the boundary (1e-6 m);
    ``brake`` defaults to ``a_x_d``."""
    rng = np.random.default_rng(10 + seed)
    n = 500
    slack, v_f, v_l = _rows(rng, n)
    lead = np.where(rng.random(n) < 0.2, PRM.a_x_d, rng.uniform(0.5, PRM.a_x_d, n))
    a = rng.uniform(-PRM.a_x_d, PRM.a_x_a, n)
    for brake in (None, 6.0, 9.5):
        b = PRM.a_x_d if brake is None else brake
        ref = ref_ok(a, slack, v_f, v_l, lead, np.full(n, b))
        clear = np.abs(ref) > 1e-6
        got = responsible_ok(a, slack, v_f, v_l, lead, PRM, brake=brake)
        np.testing.assert_array_equal(got[clear], ref[clear] >= 0.0)
        assert (got & clear).sum() > 50 and (~got & clear).sum() > 50
    # Where the check fails with brake 6 and passes with 9.5, the brake argument is what decides.
    soft = responsible_ok(a, slack, v_f, v_l, lead, PRM, brake=6.0)
    hard = responsible_ok(a, slack, v_f, v_l, lead, PRM, brake=9.5)
    assert (hard & ~soft).sum() > 5 and not (soft & ~hard).any()


def test_responsible_ok_tolerance_applies_to_the_period():
    """A gap that dips ``1e-7`` m inside the margin during the period fails without a tolerance and passes with
    ``tol = 1e-6``. Follower at 20.1 m/s braking at 2 (``a = -2``), leader at 20 m/s cruising (decel 0): the gap
    ``s − 0.1 t + t²`` is smallest at ``t = 0.05`` s, ``s − 0.0025`` m, and back to ``s`` at the period's end; after
    it the follower (19.9 m/s) is slower than a leader that never stops, so only the period can fail."""
    slack = np.array([0.0025 - 1e-7, 0.0025 + 1e-7])
    args = (np.full(2, -2.0), slack, np.full(2, 20.1), np.full(2, 20.0), np.zeros(2))
    in_period = pair_min_gap(slack, np.full(2, 20.1), np.full(2, -2.0), np.full(2, 20.0), np.zeros(2), PRM.dt)
    np.testing.assert_allclose(in_period, [-1e-7, 1e-7], atol=1e-12)
    np.testing.assert_array_equal(responsible_ok(*args, PRM), [False, True])
    np.testing.assert_array_equal(responsible_ok(*args, PRM, tol=1e-6), [True, True])
    np.testing.assert_array_equal(responsible_ok(*args, PRM, tol=0.5e-7), [False, True])


@pytest.mark.parametrize("seed", range(2))
def test_responsible_bound_with_a_softer_brake_is_the_largest_safe_acceleration(seed):
    """For ``lead_decel <= brake <= a_x_d`` the closed form is exact: the reference's check (bisection on ``a``
    over ``[−30, 30]`` m/s², the check being monotone in ``a``) finds the same largest ``a`` to 1e-6 m/s²."""
    rng = np.random.default_rng(20 + seed)
    n = 300
    slack, v_f, v_l = _rows(rng, n)
    slack = np.abs(slack) + 0.01
    lead = rng.uniform(0.0, 5.0, n)
    lead[::9] = 0.0
    brake = lead + rng.uniform(0.0, PRM.a_x_d - 5.0, n) + np.where(rng.random(n) < 0.2, 0.0, 1.0)
    lo, hi = np.full(n, -30.0), np.full(n, 30.0)
    ok_lo = ref_ok(lo, slack, v_f, v_l, lead, brake) >= 0.0
    for _ in range(45):
        mid = 0.5 * (lo + hi)
        ok = ref_ok(mid, slack, v_f, v_l, lead, brake) >= 0.0
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    got = responsible_bound(slack, v_f, v_l, lead, PRM, brake=brake)
    finite = ok_lo & (hi < 29.0)
    np.testing.assert_allclose(got[finite], lo[finite], atol=1e-6)
    assert finite.sum() > 0.2 * n
    # Where no a in [-30, 30] is too much (the leader never stops and is never caught), the bound is above 30.
    assert (got[ok_lo & (hi >= 29.0)] >= 29.0).all()
    # The default brake is a_x_d.
    np.testing.assert_array_equal(responsible_bound(slack, v_f, v_l, lead, PRM),
                                  responsible_bound(slack, v_f, v_l, lead, PRM, brake=PRM.a_x_d))  # fmt: skip
    assert (responsible_bound(slack, v_f, v_l, lead, PRM) != got).sum() > 0.5 * n


@pytest.mark.parametrize("brake", [3.0, 8.0, 12.0])
def test_final_stop_accel_with_any_brake_stops_at_the_leaders_stop(brake):
    """The follower (``a`` for one period, then ``brake`` to rest) stops exactly where the leader does, for rows
    where that ``a`` keeps it moving through the period and for rows where it stops inside the period."""
    rng = np.random.default_rng(int(brake))
    n = 200
    slack, v_f, v_l = rng.uniform(0.5, 40.0, n), rng.uniform(0.0, 35.0, n), rng.uniform(0.0, 35.0, n)
    lead = rng.uniform(0.5, 8.0, n)
    slack[::5], v_f[::5], v_l[::5] = rng.uniform(0.05, 1.0, n // 5), rng.uniform(10.0, 35.0, n // 5), 0.0
    a = final_stop_accel(slack, v_f, v_l, lead, PRM, brake=brake)
    leader_stop = slack + v_l * v_l / (2.0 * lead)
    dt = PRM.dt
    w = v_f + a * dt
    in_period = w < 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        stop = np.where(in_period, v_f * v_f / (2.0 * np.abs(a)), (v_f + w) * dt / 2.0 + w * w / (2.0 * brake))
    np.testing.assert_allclose(stop, leader_stop, rtol=1e-9, atol=1e-9)
    assert in_period.sum() > 3 and (~in_period).sum() > 50


def test_final_stop_accel_edges():
    """Both at the same stop, the follower at rest: 0. Inside the margin: ``-inf``. A leader that never stops:
    ``+inf``. A stopped leader exactly at the margin with the follower moving: ``-inf``. A stopped leader ahead
    (``Y`` = slack): the follower must stop within it."""
    z = np.zeros(1)
    one = lambda x: np.full(1, float(x))  # noqa: E731
    assert final_stop_accel(z, z, z, one(5.0), PRM)[0] == 0.0
    assert final_stop_accel(one(-0.5), z, z, one(5.0), PRM)[0] == -np.inf
    assert final_stop_accel(z, one(3.0), z, one(5.0), PRM)[0] == -np.inf
    assert final_stop_accel(one(1.0), one(30.0), one(30.0), z, PRM)[0] == np.inf
    assert final_stop_accel(one(1.0), z, one(3.0), z, PRM)[0] == np.inf
    # Stopped leader 10 m ahead, follower at 10 m/s: it stops within the period iff a = -100/20 = -5 (w = 9.5 > 0,
    # so it moves through: (10 + w) 0.05 + w²/16 = 10 -> w = -0.4 + sqrt(0.16 + 16·(10 − 0.5))... by the formula
    # with B = 8: w = -0.4 + sqrt(0.16 + 8·(20 − 1)) = -0.4 + sqrt(152.16)).
    w = -0.4 + np.sqrt(0.16 + 8.0 * 19.0)
    assert final_stop_accel(one(10.0), one(10.0), z, one(5.0), PRM)[0] == pytest.approx((w - 10.0) / 0.1, rel=1e-12)
    # A stopped leader's deceleration does not matter (0 included: it stays where it is).
    assert final_stop_accel(one(10.0), one(10.0), z, z, PRM)[0] == pytest.approx((w - 10.0) / 0.1, rel=1e-12)
    assert final_stop_accel(z, z, z, z, PRM)[0] == 0.0
    # Follower at 20 m/s, stopped leader 1 m ahead: w would be negative, so it stops inside the period at
    # v²/(2|a|) = 1: a = -200.
    assert final_stop_accel(one(1.0), one(20.0), z, one(5.0), PRM)[0] == pytest.approx(-200.0, rel=1e-12)


def test_responsible_accel_caps_at_the_wish_and_floors_at_a_x_d():
    """Where the wish is safe it is returned as is; where the bound binds, the answer is the bound less
    ``ROOT_EPS_MPS2``; where nothing is safe, ``-a_x_d``."""
    rng = np.random.default_rng(4)
    n = 400
    slack, v_f, v_l = _rows(rng, n)
    lead = rng.uniform(0.0, PRM.a_x_d, n)
    wanted = rng.uniform(-PRM.a_x_d, PRM.a_x_a, n)
    a = responsible_accel(wanted, slack, v_f, v_l, lead, PRM)
    ref = ref_ok(wanted, slack, v_f, v_l, lead, np.full(n, PRM.a_x_d))
    safe_wish = ref > 1e-6
    np.testing.assert_array_equal(a[safe_wish], wanted[safe_wish])
    unsafe_wish = ref < -1e-6
    assert (a[unsafe_wish] < wanted[unsafe_wish]).all()
    floor = ref_ok(np.full(n, -PRM.a_x_d), slack, v_f, v_l, lead, np.full(n, PRM.a_x_d)) < -1e-6
    np.testing.assert_array_equal(a[floor], -PRM.a_x_d)
    assert floor.sum() > 10 and safe_wish.sum() > 50
    binds = unsafe_wish & ~floor
    bound = np.min(np.stack(list(responsible_bounds(slack, v_f, v_l, lead, PRM).values())), 0)
    np.testing.assert_array_equal(a[binds], np.maximum(bound[binds] - ROOT_EPS_MPS2, -PRM.a_x_d))
    # The answer passes the reference's check (safe) and 1e-6 more does not (maximal).
    assert (ref_ok(a[binds], slack[binds], v_f[binds], v_l[binds], lead[binds], PRM.a_x_d) >= -1e-9).all()
    assert (ref_ok(a[binds] + 1e-6, slack[binds], v_f[binds], v_l[binds], lead[binds], PRM.a_x_d) < 0.0).all()
    # Scalars broadcast.
    assert np.shape(responsible_accel(1.0, 5.0, 20.0, 20.0, PRM.a_x_d, PRM)) == ()


def test_responsible_accel_with_a_softer_brake_floors_at_it_and_is_safe_under_it():
    """``brake`` (another vehicle following brakes at up to ``a_o_d``, not ``a_x_d``): the answer is the wish where
    that is safe under ``brake``, the floor ``-brake`` where nothing is, and in between passes the reference's check
    braking at ``brake`` — a check that braking at ``a_x_d`` would fail on a part of the rows."""
    rng = np.random.default_rng(9)
    n = 400
    slack, v_f, v_l = _rows(rng, n)
    lead = rng.uniform(0.0, 3.0, n)
    brake = np.full(n, 4.0)
    wanted = rng.uniform(-4.0, PRM.a_x_a, n)
    a = responsible_accel(wanted, slack, v_f, v_l, lead, PRM, brake=4.0)
    floor = ref_ok(np.full(n, -4.0), slack, v_f, v_l, lead, brake) < -1e-6
    np.testing.assert_array_equal(a[floor], -4.0)
    assert floor.sum() > 10 and a.min() == -4.0
    safe = ~floor
    assert (ref_ok(a[safe], slack[safe], v_f[safe], v_l[safe], lead[safe], brake[safe]) >= -1e-9).all()
    # The default (a_x_d) answers differently on many rows: the brake is read.
    differs = a != responsible_accel(wanted, slack, v_f, v_l, lead, PRM)
    assert differs.sum() > 0.2 * n


def test_a_wish_exactly_at_the_bound_is_taken_on_the_safe_side():
    """``responsible_accel`` applies the closed-form bound ``ROOT_EPS_MPS2`` on the safe side (rounding at the
    boundary): a wish exactly equal to the bound is not taken as is; a wish just above it neither; one below it is.
    Hand case: leader stopped 10 m beyond the margin, follower at 10 m/s: the final stop binds, ``a = (w − 10)/0.1``
    with ``w = −0.4 + sqrt(0.16 + 8·19)`` (see ``test_final_stop_accel_edges``)."""
    one = lambda x: np.full(1, float(x))  # noqa: E731
    row = (one(10.0), one(10.0), one(0.0), one(5.0))
    bound = (-0.4 + np.sqrt(0.16 + 8.0 * 19.0) - 10.0) / 0.1
    assert responsible_bound(*row, PRM)[0] == pytest.approx(bound, rel=1e-12)
    exact = responsible_bound(*row, PRM)
    assert responsible_accel(exact, *row, PRM)[0] == exact[0] - ROOT_EPS_MPS2
    assert responsible_accel(exact + 1e-3, *row, PRM)[0] == exact[0] - ROOT_EPS_MPS2
    assert responsible_accel(exact - 1e-3, *row, PRM)[0] == exact[0] - 1e-3


def test_a_follower_at_rest_needs_no_braking():
    """A follower at rest staying at rest (``a = 0``) behind a stopped leader 5 m beyond the margin needs no braking
    at all: the check passes with ``brake = 0`` (the required deceleration, 0, is at most the brake); moving off
    at 1 m/s² it needs some, so ``brake = 0`` fails."""
    one = lambda x: np.full(1, float(x))  # noqa: E731
    assert responsible_ok(one(0.0), one(5.0), one(0.0), one(0.0), one(8.0), PRM, brake=0.0)[0]
    assert not responsible_ok(one(1.0), one(5.0), one(0.0), one(0.0), one(8.0), PRM, brake=0.0)[0]


def test_the_bounds_raise_no_floating_point_warnings():
    """Equal speeds (the in-period vertex divides by ``v_f − v_l`` = 0), zero slack, stopped vehicles, a leader
    that never brakes: the closed forms divide raw and mask after, silently."""
    rows = [np.array(c, dtype=float) for c in zip(*[
        (0.0, 10.0, 10.0, 3.0), (-0.0, 9.25, 9.0, 0.0), (5.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 8.0),
        (2.0, 20.0, 20.0, 0.0), (-1.0, 5.0, 0.0, 8.0),
    ], strict=True)]  # fmt: skip
    with np.errstate(all="raise"):
        out = responsible_bound(*rows, PRM)
        responsible_accel(np.zeros(6), *rows, PRM)
    assert out.shape == (6,) and not np.isnan(out).any()


def test_the_bounds_are_named_as_documented():
    """``responsible_bounds``' cases by the names its docstring gives them, in that order (the first binding one is
    the reported reason)."""
    bounds = responsible_bounds(np.array([5.0]), np.array([20.0]), np.array([18.0]), np.array([3.0]), PRM)
    assert list(bounds) == ["inside", "final", "end", "in_period", "after_period"]


def test_a_follower_at_rest_at_the_leaders_stop_may_stay_exactly():
    """The docstring's tie: both stop at the same point and the follower is already there at rest — staying
    (``a = 0``, exactly; not the round-off of the moving root) is the bound, for any brake. (With ``brake = 0.09``
    the moving root's ``sqrt(0.25 B² dt²) − 0.5 B dt`` is 8.7e-19, not 0: the tie must be decided before it.)"""
    for brake in (PRM.a_x_d, 3.0, 0.5, 0.09):
        for lead_decel in (0.0, 3.0):
            a = final_stop_accel(np.array([0.0]), np.array([0.0]), np.array([0.0]), np.array([lead_decel]), PRM,
                                 brake=np.array([brake]))  # fmt: skip
            assert a[0] == 0.0


def test_a_leader_that_never_stops_never_bounds_the_final_stop_whatever_the_brake():
    """A leader that never stops (not braking, moving): no final-stop constraint — ``+inf`` — even for a follower
    that cannot brake at all afterwards (``brake = 0``)."""
    for brake in (0.0, 0.5, PRM.a_x_d):
        a = final_stop_accel(np.array([10.0]), np.array([10.0]), np.array([10.0]), np.array([0.0]), PRM,
                             brake=np.array([brake]))  # fmt: skip
        assert a[0] == np.inf


@pytest.mark.filterwarnings("error")
def test_final_stop_accel_raises_no_floating_point_warning_at_extreme_finite_inputs():
    huge = np.array([1e200, 1e-300, 0.0])
    a = final_stop_accel(np.array([10.0, 1e200, 0.0]), huge, huge, np.array([3.0, 1e-300, 8.0]), PRM)
    assert a.shape == (3,)


def test_no_acceleration_keeps_the_end_gap_behind_a_leader_already_past_the_margin_at_dt():
    """``end`` (the gap zero at ``dt``): where the leader's gap position at ``dt`` is already negative (inside the
    margin, leader stopped or slow), no acceleration of the follower makes the gap zero there: the bound is ``−inf``;
    exactly at zero with the follower at rest it is ``0`` (staying)."""
    rows = ([-2.0, -0.5, 0.0], [10.0, 0.0, 0.0], [0.0, 1.0, 0.0], [3.0, 8.0, 3.0])  # slack, v_f, v_l, lead
    slack, v_f, v_l, lead = (np.array(x) for x in rows)
    end = responsible_bounds(slack, v_f, v_l, lead, PRM)["end"]
    assert end[0] == -np.inf and end[1] == -np.inf and end[2] == 0.0
