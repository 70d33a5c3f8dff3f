"""The helpers of ``safelane.shield.realworld`` one by one, against independent computations: the own lane's
worst-case deceleration against the bisection chain reference (``tests/reference.py``), the sensing corners field
by field, the own-lane replanning row by row, the commands issued and in flight against plain kinematics.
Seeded, small batches: fast."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from reference import ref_leader_chain
from safelane import Params
from safelane.safety import plan_evasion
from safelane.safety.own_lane import own_lane_core
from safelane.shield import Situation
from safelane.shield.command import Command, InFlight
from safelane.shield.decide import own_margin
from safelane.shield.realworld import (
    carry_worst,
    chain_bounds,
    in_flight_checked,
    own_lane_decel,
    own_plan,
    worst_corners,
)


def _own_situation(rng, prm: Params, b: int, k: int = 3, errors: bool = False) -> Situation:
    """A batch with an own-lane chain of ``k`` vehicles (L0 first) close ahead, tight gaps (some inside the
    margin), some connected, promises in ``[0, a_x_d]``; L1 and F far (not read here)."""
    ex = rng.uniform(-20.0, 20.0, b)
    ev = rng.uniform(0.0, 35.0, b)
    ox = ex[:, None] + np.cumsum(rng.uniform(prm.p_m - 2.0, prm.p_m + 25.0, (b, k)), axis=1)
    ov = np.maximum(ev[:, None] + rng.normal(0.0, 6.0, (b, k)), 0.0)
    ov[::7, 1] = 0.0
    s = Situation.from_arrays(
        t=0.0, ego=(ex, np.zeros(b), ev, np.zeros(b)), follower=(ex - 300.0, np.zeros(b)),
        leaders=(ex[:, None] + 300.0, np.full((b, 1), 30.0)), n_connected=0, own_leaders=(ox, ov),
        own_n_connected=rng.integers(0, k, b), own_promise=rng.uniform(0.0, prm.a_x_d, (b, k - 1)), params=prm,
    )  # fmt: skip
    if errors:
        e = np.stack([rng.uniform(0.0, 1.5, (b, k)), rng.uniform(0.0, 1.0, (b, k))], -1)
        s = dataclasses.replace(s, err_own=e)
    return s


def _ref_own_bound(s: Situation, prm: Params):
    """L0's bound by the reference: the chain analysis (bisection) of the own lane's chain, promises of vehicles
    beyond the connected ones replaced by ``a_x_d``; ``a_x_d`` where the chain is unsafe."""
    k = s.own_x.shape[1]
    in_chain = np.arange(k - 1)[None, :] < s.own_n_connected[:, None]
    promise = np.where(in_chain, s.own_promise, prm.a_x_d)
    ref = ref_leader_chain(s.own_x, s.own_v, promise, prm)
    return ref.l1_decel, ref.unsafe


@pytest.mark.parametrize("seed", range(2))
def test_own_lane_decel_is_the_own_chains_bound_when_informed_and_unbroken(seed):
    """``informed & ~broken``: the reference's L0 bound (``a_x_d`` where the chain is unsafe); otherwise
    ``a_x_d``, whatever the chain."""
    prm = Params()
    rng = np.random.default_rng(seed)
    b = 120
    s = _own_situation(rng, prm, b)
    ref, unsafe = _ref_own_bound(s, prm)
    assert unsafe.sum() >= 5 and (ref < prm.a_x_d - 0.5).sum() >= 20, (unsafe.sum(), (ref < prm.a_x_d).sum())
    informed = rng.random(b) < 0.6
    broken = rng.random(b) < 0.3
    got = own_lane_decel(s, prm, informed, broken)
    want = np.where(informed & ~broken, ref, prm.a_x_d)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)
    # Every combination occurs where the bound is below a_x_d (so a wrong combination shows).
    below = ref < prm.a_x_d - 0.1
    for i_val in (True, False):
        for b_val in (True, False):
            assert (below & (informed == i_val) & (broken == b_val)).any()
    # The unsafe rows with a bound below a_x_d at L0 (an unsafe link further ahead) take a_x_d, informed or not.
    bounds, unsafe_e = chain_bounds(s.own_x, s.own_v, s.own_promise, s.own_n_connected, np.zeros((b, 2), bool), None,
                                    prm)  # fmt: skip
    np.testing.assert_array_equal(unsafe_e, unsafe)
    assert (unsafe & (bounds[:, 0] < prm.a_x_d)).any()
    assert np.all(got[unsafe] == prm.a_x_d)


def test_chain_bounds_per_link_corner_against_the_reference():
    """With errors, each link at its own worst corner: link ``i``'s follower ``e_i`` further ahead and ``ev_i``
    faster, its leader ``e_{i+1}`` further back and ``ev_{i+1}`` slower (not below 0) — the reference's pairwise
    bisection, link by link from the front, gives the same bounds and verdict."""
    from reference import ref_min_follow_decel

    prm = Params()
    rng = np.random.default_rng(5)
    b, k = 150, 3
    s = _own_situation(rng, prm, b, k, errors=True)
    e = s.err_own
    human = rng.random((b, k - 1)) < 0.3
    n_conn = s.own_n_connected
    bounds, unsafe = chain_bounds(s.own_x, s.own_v, s.own_promise, n_conn, human, e, prm)
    in_chain = np.arange(k - 1)[None, :] < n_conn[:, None]
    promise = np.where(in_chain, s.own_promise, prm.a_x_d)
    margin = np.where(human & in_chain, prm.p_m_human, prm.p_m)
    a_ahead = np.full(b, prm.a_x_d)
    want = [a_ahead]
    bad = np.zeros(b, bool)
    for i in range(k - 2, -1, -1):
        v_lead = np.maximum(s.own_v[:, i + 1] - e[:, i + 1, 1], 0.0)
        p_f, v_f, p_l = s.own_x[:, i] + e[:, i, 0], s.own_v[:, i] + e[:, i, 1], s.own_x[:, i + 1] - e[:, i + 1, 0]
        r = ref_min_follow_decel(p_f, v_f, p_l, v_lead, a_ahead, margin[:, i], prm.a_x_d)
        bad |= ~(r.z <= prm.a_x_d)
        a_ahead = np.minimum(np.maximum(promise[:, i], r.z), prm.a_x_d)
        want.insert(0, a_ahead)
    np.testing.assert_allclose(bounds, np.column_stack(want), rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(unsafe, bad)
    assert bad.any() and (~bad).any() and (np.column_stack(want)[:, 0] < prm.a_x_d - 0.5).any()


def test_worst_corners_every_field_and_missing_bounds():
    """Leaders low and slow (speeds not below 0), F high and fast for the analysis; the opposite corners for the
    observation; a missing error array counts as zero; without any, both are the situation itself."""
    prm = Params()
    rng = np.random.default_rng(2)
    b, m, k = 30, 3, 2
    ex = rng.uniform(-5, 5, b)
    s = Situation.from_arrays(
        t=0.0, ego=(ex, np.zeros(b), np.full(b, 20.0), np.zeros(b)), follower=(ex - 20.0, rng.uniform(0.0, 1.0, b)),
        leaders=(ex[:, None] + 20.0 * np.arange(1, m + 1), rng.uniform(0.0, 1.0, (b, m))), n_connected=0,
        own_leaders=(ex[:, None] + 15.0 * np.arange(1, k + 1), rng.uniform(0.0, 1.0, (b, k))), params=prm,
    )  # fmt: skip
    ef = np.stack([rng.uniform(0, 2, b), rng.uniform(0, 2, b)], -1)
    ec = np.stack([rng.uniform(0, 2, (b, m)), rng.uniform(0, 2, (b, m))], -1)
    eo = np.stack([rng.uniform(0, 2, (b, k)), rng.uniform(0, 2, (b, k))], -1)
    full = dataclasses.replace(s, err_f=ef, err_chain=ec, err_own=eo)
    low, high = worst_corners(full)
    np.testing.assert_array_equal(low.chain_x, s.chain_x - ec[..., 0])
    np.testing.assert_array_equal(low.chain_v, np.maximum(s.chain_v - ec[..., 1], 0.0))
    np.testing.assert_array_equal(low.f_x, s.f_x + ef[:, 0])
    np.testing.assert_array_equal(low.f_v, s.f_v + ef[:, 1])
    np.testing.assert_array_equal(low.own_x, s.own_x - eo[..., 0])
    np.testing.assert_array_equal(low.own_v, np.maximum(s.own_v - eo[..., 1], 0.0))
    np.testing.assert_array_equal(high.chain_x, s.chain_x + ec[..., 0])
    np.testing.assert_array_equal(high.chain_v, s.chain_v + ec[..., 1])
    np.testing.assert_array_equal(high.f_x, s.f_x - ef[:, 0])
    np.testing.assert_array_equal(high.f_v, np.maximum(s.f_v - ef[:, 1], 0.0))
    np.testing.assert_array_equal(high.own_x, s.own_x + eo[..., 0])
    np.testing.assert_array_equal(high.own_v, s.own_v + eo[..., 1])
    assert (low.chain_v == 0.0).any() and (high.f_v == 0.0).any() and (low.own_v == 0.0).any()
    for corner in (low, high):  # the ego and everything else untouched
        for name in ("ego_x", "ego_y", "ego_vx", "ego_vy", "chain_promise", "n_connected"):
            np.testing.assert_array_equal(getattr(corner, name), getattr(s, name))
    # Each error array alone (the others None: zero).
    for field, changed in (("err_f", ("f_x", "f_v")), ("err_chain", ("chain_x", "chain_v")),
                           ("err_own", ("own_x", "own_v"))):  # fmt: skip
        one = dataclasses.replace(s, **{field: getattr(full, field)})
        lo1, hi1 = worst_corners(one)
        for name in ("f_x", "f_v", "chain_x", "chain_v", "own_x", "own_v"):
            for c1, cf in ((lo1, low), (hi1, high)):
                want = getattr(cf, name) if name in changed else getattr(s, name)
                np.testing.assert_array_equal(getattr(c1, name), want, err_msg=f"{field}: {name}")
    # No own lane: the corners carry none.
    no_own = dataclasses.replace(full, own_x=None, own_v=None, own_promise=None, own_n_connected=None, err_own=None)
    lo2, hi2 = worst_corners(no_own)
    assert lo2.own_x is None and hi2.own_x is None
    np.testing.assert_array_equal(lo2.chain_x, low.chain_x)
    assert worst_corners(s) == (s, s)


def _plan_args(rng, prm, b):
    ex = np.zeros(b)
    ey = rng.uniform(0.0, prm.lane_width, b)
    ev = rng.uniform(5.0, 35.0, b)
    evy = rng.uniform(-1.0, 1.5, b)
    l1x = prm.p_m + rng.uniform(0.0, 60.0, b)
    l1v = np.maximum(ev + rng.normal(0.0, 4.0, b), 0.0)
    fx, fv = -prm.p_m - rng.uniform(0.0, 60.0, b), rng.uniform(0.0, 40.0, b)
    return (ex, ey, ev, evy, l1x, l1v, np.full(b, prm.a_x_d), fx, fv, np.ones(b, bool))


def test_own_plan_replans_exactly_the_rows_with_an_l0():
    """Rows with L0 (finite position) take the own-lane check's verdict and parts; rows without keep the paper's
    plan field for field (a row without L0 has a finite speed, 0: only the position says it is absent)."""
    prm = Params()
    rng = np.random.default_rng(8)
    b = 80
    args = _plan_args(rng, prm, b)
    ox = prm.p_m + rng.uniform(0.0, 40.0, b)
    ox[::3] = np.inf
    ov = np.where(np.isfinite(ox), np.maximum(args[2] + rng.normal(0.0, 4.0, b), 0.0), 0.0)
    od = rng.uniform(1.0, prm.a_x_d, b)
    plan = plan_evasion(*args, prm)
    out = own_plan(plan, args, (ox, ov, od), prm)
    has = np.isfinite(ox)
    for f in dataclasses.fields(plan):
        if f.name == "params":
            assert out.params == prm
            continue
        np.testing.assert_array_equal(getattr(out, f.name)[~has], getattr(plan, f.name)[~has], err_msg=f.name)
    margin = own_margin(prm)
    exists, parts = own_lane_core(*(a[has] for a in args), ox[has], ov[has], od[has], prm.p_m, prm.p_m, margin, prm)
    np.testing.assert_array_equal(out.feasible[has], exists)
    np.testing.assert_array_equal(out.t_x1[has], parts["t_x1"])
    np.testing.assert_array_equal(out.follows_own[has], parts["follows_own"])
    np.testing.assert_array_equal(out.min_gap_own[has], parts["own_gap"] + margin)
    np.testing.assert_array_equal(out.own_p[has], ox[has])
    assert out.continues[has].all() and not out.continues[~has].any()
    assert exists.any() and (~exists).any() and (out.feasible[has] != plan.feasible[has]).any()


def test_carry_worst_brakes_to_rest_or_accelerates():
    """Constant acceleration ``-decel`` for ``horizon``, stopping at rest (hand kinematics)."""
    x, v = np.array([0.0, 10.0, 0.0, 5.0]), np.array([20.0, 2.0, 10.0, 0.0])
    decel = np.array([8.0, 8.0, -2.5, 8.0])
    got_x, got_v = carry_worst(x, v, decel, 0.3)
    np.testing.assert_allclose(got_x, [20 * 0.3 - 4 * 0.09, 10.0 + 4.0 / 16.0, 3.0 + 1.25 * 0.09, 5.0], rtol=1e-12)
    np.testing.assert_allclose(got_v, [20 - 2.4, 0.0, 10.75, 0.0], rtol=1e-12)
    # A scalar decel (the shield's L1 at a_x_d) broadcasts.
    got_x, got_v = carry_worst(x[:2], v[:2], 8.0, 0.3)
    np.testing.assert_allclose(got_v, [17.6, 0.0], rtol=1e-12)


def test_a_commands_piece():
    """An aborting row's knots ``(t, v_x, v_y)`` become segment durations and the constant accelerations between
    them; a zero-length segment has acceleration 0. Another row's piece is ``(dt, a_x, a_y)`` in the first
    segment (the others empty; one segment where no row aborts)."""
    knots = np.array([[0.0, 0.02, 0.02, 0.05, 0.1, 0.1, 0.1, 0.1], [0.0, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]])
    vx = np.array([[20.0, 19.8, 19.8, 19.5, 19.0, 19.0, 30.0, 19.0], [10.0, 10.25, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0]])
    vy = np.array([[1.0, 0.97, 0.97, 0.94, 0.94, 0.94, 0.94, 0.94], [0.0, 0.15, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    rows = np.arange(2)
    with np.errstate(all="raise"):  # zero-length segments are never divided by (no warning, no nan)
        dur, ax, ay = Command.issued(np.zeros(2), np.zeros(2), (rows, knots, None, vx, None, vy), rows < 0).piece(0.1)
    np.testing.assert_allclose(dur, np.diff(knots, axis=1), atol=1e-15)
    np.testing.assert_allclose(ax[0], [-10.0, 0.0, -10.0, -10.0, 0.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(ay[0], [-1.5, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(ax[1], [2.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(ay[1], [1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], atol=1e-9)
    dt = 0.1
    ax_cmd, ay_cmd = np.array([1.0, -2.0, 0.5]), np.array([0.3, -0.4, 0.0])
    none = (np.array([], np.int64), None, None, None, None, None)
    d, a, y = Command.issued(ax_cmd, ay_cmd, none, np.zeros(3, bool)).piece(dt)
    assert d.shape == a.shape == y.shape == (3, 1)
    np.testing.assert_array_equal(d[:, 0], dt)
    np.testing.assert_array_equal(a[:, 0], ax_cmd)
    np.testing.assert_array_equal(y[:, 0], ay_cmd)
    abort = (np.array([2]), knots[:1], None, vx[:1], None, vy[:1])
    d, a, y = Command.issued(ax_cmd, ay_cmd, abort, np.zeros(3, bool)).piece(dt)
    np.testing.assert_allclose(d[2], dur[0], atol=1e-15)
    np.testing.assert_allclose(a[2], ax[0], atol=1e-9)
    np.testing.assert_allclose(y[2], ay[0], atol=1e-9)
    np.testing.assert_array_equal(a[:2, 0], ax_cmd[:2])
    assert d.shape == (3, 7)
    np.testing.assert_array_equal(d[:2, 1:], 0.0)
    # Carrying the issued piece moves the ego as the commands say (cruise segments of zero length change nothing).
    p = InFlight(commands=(Command.issued(ax_cmd, ay_cmd, none, np.zeros(3, bool)),))
    x, y, v, w = p.carry(np.zeros(3), np.zeros(3), np.array([20.0, 10.0, 0.0]), np.zeros(3), dt)
    np.testing.assert_allclose(v, [20.1, 9.8, 0.05], rtol=1e-12)
    np.testing.assert_allclose(x, [2.0 + 0.005, 1.0 - 0.01, 0.0025], rtol=1e-12)
    np.testing.assert_allclose(w, [0.03, -0.04, 0.0], rtol=1e-12)
    np.testing.assert_allclose(y, [0.0015, -0.002, 0.0], rtol=1e-12)


def _in_flight_situation(prm, ey, evy, l1_gap, l1_v, f_gap, f_v, ev=20.0, own=None):
    b = len(ey)
    ex = np.zeros(b)
    return Situation.from_arrays(
        t=0.0, ego=(ex, ey, np.full(b, ev), evy), follower=(ex - f_gap, f_v), leaders=(l1_gap[:, None], l1_v[:, None]),
        n_connected=0, own_leaders=own, params=prm,
    )  # fmt: skip


def test_in_flight_checked_by_hand():
    """Cruise for the delay δ = 0.3 s at 20 m/s. To L1 (braking at ``a_x_d`` = 8 from 20 m/s) the gap shrinks by
    ``8·0.09/2`` = 0.36 m, from the worst-case F (aggressive, 20 m/s, +2.5 m/s²) by ``2.5·0.09/2`` = 0.1125 m: a
    row fails iff it is in the conflict zone during the delay (``y`` beyond ``y_s`` + 1e-9 m at some instant)
    and a slack is below that. To L0 (braking at its own decel) throughout, lateral position or not."""
    prm = Params()
    delay = 0.3
    y_in, y_out = prm.y_safe + 0.5, 0.0
    # rows: (ey, evy, L1 slack, F slack)
    rows = [
        (y_in, 0.0, 0.37, 0.2),  # conflict, both fine
        (y_in, 0.0, 0.35, 0.2),  # conflict, L1 too close
        (y_in, 0.0, 0.37, 0.1),  # conflict, F too close
        (y_out, 0.0, 0.35, 0.1),  # out of the zone throughout: fine
        (0.5, 2.0, 0.35, 0.2),  # enters the zone within the delay (1.1 m > y_s = 0.85 m): L1 too close
        (prm.y_safe + 0.5e-9, 0.0, 0.35, 0.1),  # within y_s + LATERAL_TOL_M (1e-9 m): not in conflict
    ]
    ey, evy, sl, sf = (np.array(c) for c in zip(*rows, strict=True))
    b = len(rows)
    s = _in_flight_situation(prm, ey, evy, prm.p_m + sl, np.full(b, 20.0), prm.p_m + sf, np.full(b, 20.0))
    plan = plan_evasion(np.zeros(b), ey, np.full(b, 20.0), evy, prm.p_m + 50.0, 20.0, 0.0, -prm.p_m - 50.0, 0.0,
                        False, prm)  # fmt: skip
    plan = dataclasses.replace(plan, feasible=np.ones(b, bool))
    got = in_flight_checked(plan, s, None, delay, prm).feasible
    np.testing.assert_array_equal(got, [True, False, False, True, False, True])
    # Infeasible plans stay infeasible.
    none = in_flight_checked(dataclasses.replace(plan, feasible=np.zeros(b, bool)), s, None, delay, prm).feasible
    assert not none.any()
    # L0 at 20 m/s braking at 4 (the gap shrinks by 4·0.09/2 = 0.18 m), at rows out of the zone; no L0 at row 1.
    ox = np.array([prm.p_m + 0.19, np.inf, prm.p_m + 0.17, prm.p_m + 0.19, prm.p_m + 0.17, prm.p_m + 0.5])
    ov = np.where(np.isfinite(ox), 20.0, 0.0)
    far = _in_flight_situation(prm, np.zeros(b), np.zeros(b), np.full(b, 100.0), np.full(b, 20.0),
                               np.full(b, 100.0), np.zeros(b))  # fmt: skip
    got = in_flight_checked(plan, far, (ox, ov, np.full(b, 4.0)), delay, prm).feasible
    np.testing.assert_array_equal(got, [True, True, False, True, False, True])
    # The L0 check uses L0's own decel: braking at 0 it keeps every gap.
    got = in_flight_checked(plan, far, (ox, ov, np.zeros(b)), delay, prm).feasible
    assert got.all()


def test_in_flight_checked_at_the_boundaries():
    """Gaps exactly ``-tol`` (``FEASIBILITY_TOL_M`` = 1e-9 m; ``-tol/2`` to L0) count as kept, a lateral position
    exactly ``y_s + LATERAL_TOL_M`` is out of the conflict zone, and only positions relative to the ego count (the
    ego at x = 100 m). The exact gaps: L1 stopped exactly at the margin, the ego creeping at ``1e-9/0.3`` m/s
    (``fl(v·0.3)`` = 1e-9 exactly) closes 1e-9 m over δ = 0.3 s; F at rest exactly at the margin, accelerating at
    ``a_x_a`` = 2.5 over δ = sqrt(1e-9/1.25) s, closes ``1.25 δ²`` = 1e-9 m (exactly, in floats, for this δ); L0
    stopped at the margin with the ego at ``0.5e-9/0.3`` m/s closes 0.5e-9 m."""
    from safelane.safety.lateral import LATERAL_TOL_M

    prm = Params()
    x0 = 100.0
    y_in = prm.y_safe + 0.5
    creep = 1e-9 / 0.3
    assert creep * 0.3 == 1e-9
    b = 4
    # rows: L1 exactly -tol in the zone; L1 1e-9 m further in (3e-9/0.3 m/s); exactly on the zone's edge, L1
    # closing 0.5 m; in the zone, L1 far and still.
    ey = np.array([y_in, y_in, prm.y_safe + LATERAL_TOL_M, y_in])
    ev = np.array([creep, 2.0 * creep, 0.0, 0.0])
    l1x = np.array([x0 + prm.p_m, x0 + prm.p_m, x0 + prm.p_m - 0.5, x0 + 50.0])
    plan = plan_evasion(np.full(b, x0), ey, ev, np.zeros(b), x0 + 50.0, 0.0, 0.0, x0 - 50.0, 0.0, False, prm)
    plan = dataclasses.replace(plan, feasible=np.ones(b, bool))
    s = Situation.from_arrays(
        t=0.0, ego=(np.full(b, x0), ey, ev, np.zeros(b)), follower=(np.full(b, x0 - 50.0), np.zeros(b)),
        leaders=(l1x[:, None], np.zeros((b, 1))), n_connected=0, params=prm,
    )  # fmt: skip
    np.testing.assert_array_equal(in_flight_checked(plan, s, None, 0.3, prm).feasible, [True, False, True, True])
    # F exactly -tol after δ.
    delay = float(np.sqrt(1e-9 / 1.25))
    f_far = Situation.from_arrays(
        t=0.0, ego=(np.full(b, x0), np.full(b, y_in), np.zeros(b), np.zeros(b)),
        follower=(np.array([x0 - prm.p_m, x0 - prm.p_m + 1e-9, x0 - 50.0, x0 - 50.0]), np.zeros(b)),
        leaders=(np.full((b, 1), x0 + 50.0), np.zeros((b, 1))), n_connected=0, params=prm,
    )  # fmt: skip
    np.testing.assert_array_equal(in_flight_checked(plan, f_far, None, delay, prm).feasible, [True, False, True, True])
    # L0 exactly -tol/2 after δ = 0.3 s (out of the zone: L0 counts throughout), and 1e-9 m further.
    half = 0.5e-9 / 0.3
    assert half * 0.3 == 0.5e-9
    out = Situation.from_arrays(
        t=0.0, ego=(np.full(b, x0), np.zeros(b), np.array([half, 2 * half, 0.0, 0.0]), np.zeros(b)),
        follower=(np.full(b, x0 - 50.0), np.zeros(b)), leaders=(np.full((b, 1), x0 + 50.0), np.zeros((b, 1))),
        n_connected=0, params=prm,
    )  # fmt: skip
    own = (np.array([x0 + prm.p_m, x0 + prm.p_m, np.inf, x0 + 20.0]), np.zeros(b), np.full(b, prm.a_x_d))
    np.testing.assert_array_equal(in_flight_checked(plan, out, own, 0.3, prm).feasible, [True, False, True, True])


def test_chain_bounds_empty_slots_and_the_exact_unsafe_boundary():
    """Hand cases (default Params: ``a_x_d`` = 8, ``p_m`` = 7). Row 0: L0 at 8 m/s, the next vehicle stopped 4 m
    beyond the margin: it needs ``8²/(2·4)`` = 8 = ``a_x_d`` exactly, which is still safe (unsafe is *beyond*
    ``a_x_d``); the slot after it is empty (``+inf``), which leaves that vehicle free (its promise, 2). Row 1: both
    slots ahead empty: each vehicle's bound is its promise. Row 2: nobody connected: ``a_x_d`` throughout. No
    floating-point warning (``inf − inf`` of two empty slots is handled)."""
    prm = Params()
    x = np.array([[0.0, prm.p_m + 4.0, np.inf], [0.0, np.inf, np.inf], [0.0, prm.p_m + 4.0, prm.p_m + 100.0]])
    v = np.array([[8.0, 0.0, 0.0], [20.0, 0.0, 0.0], [8.0, 0.0, 0.0]])
    promise = np.array([[1.0, 2.0], [1.0, 2.0], [3.0, 3.0]])
    with np.errstate(all="raise"):
        bounds, unsafe = chain_bounds(x, v, promise, np.array([2, 2, 0]), np.zeros((3, 2), bool), None, prm)
    np.testing.assert_array_equal(bounds, [[8.0, 2.0, 8.0], [1.0, 2.0, 8.0], [8.0, 8.0, 8.0]])
    np.testing.assert_array_equal(unsafe, [False, False, False])
    # 1 cm closer, the same pair needs more than a_x_d: unsafe.
    x[0, 1] -= 0.01
    bounds, unsafe = chain_bounds(x, v, promise, np.array([2, 2, 0]), np.zeros((3, 2), bool), None, prm)
    np.testing.assert_array_equal(unsafe, [True, False, False])


def test_delay_periods_rounds_within_a_nanosecond():
    """A delay within 1e-9 s of a whole number of periods is that number (round-off of a configured float);
    beyond, refused. Exactly 1e-9 s off (the delay 1e-9 s, 0 periods: the difference is that double exactly) is
    still accepted."""
    from safelane.shield.realworld import delay_periods

    prm = Params()

    class Cfg:
        def __init__(self, delay):
            self.actuation_delay_s = delay

    assert delay_periods(Cfg(1e-9), prm) == 0
    assert delay_periods(Cfg(0.2), prm) == 2
    assert delay_periods(Cfg(0.0), prm) == 0
    with pytest.raises(ValueError, match="actuation_delay_s"):
        delay_periods(Cfg(2e-9), prm)


@dataclasses.dataclass(frozen=True)
class _Feasible:
    feasible: np.ndarray


def test_in_flight_checks_l1_and_f_only_where_the_drift_reaches_the_conflict_zone():
    """During the delay the ego drifts at its lateral speed (no lateral acceleration in flight): the gaps to L1 and F
    count only where ``max(y0, y0 + v_y·delay)`` passes ``y_safe`` (the reference: that line's two ends). L1 sits
    inside the margin in every row, so a row stays feasible exactly where the drift stays out of the zone."""
    prm = Params()
    delay = 0.2
    y0 = np.array([prm.y_safe - 0.30, prm.y_safe - 0.30, prm.y_safe - 0.05, prm.y_safe + 0.10, prm.y_safe - 1.0])
    vy = np.array([0.5, 1.6, 0.0, -1.0, 3.0])  # ends: -0.20, +0.02, -0.05, +0.10 (start inside), -0.40
    b = len(y0)
    ex = np.zeros(b)
    s = Situation.from_arrays(
        t=0.0, ego=(ex, y0, np.full(b, 20.0), vy), follower=(ex - 300.0, np.full(b, 20.0)),
        leaders=((ex + prm.p_m - 1.0)[:, None], np.full((b, 1), 20.0)), n_connected=0, params=prm,
    )  # fmt: skip
    got = in_flight_checked(_Feasible(np.ones(b, bool)), s, None, delay, prm).feasible
    reaches = np.maximum(y0, y0 + vy * delay) > prm.y_safe
    np.testing.assert_array_equal(got, ~reaches)
    assert reaches.any() and (~reaches).any()


def _worst_by_hand(x, v, acc, horizon):
    """Constant acceleration ``acc`` for ``horizon``, stopping at rest (never reversing), one vehicle at a time."""
    out = []
    for x0, v0, a in zip(x, v, acc, strict=True):
        t = horizon if a >= 0.0 or v0 + a * horizon >= 0.0 else v0 / -a
        out.append((x0 + v0 * t + 0.5 * a * t * t, max(v0 + a * t, 0.0)))
    return np.array(out).T


def test_the_delayed_frame_carries_l1_and_f_along_their_worst_cases():
    """``realworld.carried_others`` (the frame of a decision under an actuation delay): L1 brakes at its worst-case
    deceleration, F accelerates at ``a_x_a`` where it is taken for aggressive and brakes at ``a_x_d`` elsewhere; both
    stop at rest — against the kinematics written out by hand."""
    from safelane.safety._backend import ARRAY
    from safelane.shield.realworld import carried_others

    prm = Params()
    rng = np.random.default_rng(8)
    n, delay = 400, 0.3
    l1_x, l1_v, l1_decel = rng.uniform(10, 60, n), rng.uniform(0, 3, n), rng.uniform(2, 9, n)
    f_x, f_v = rng.uniform(-60, -5, n), rng.uniform(0, 3, n)
    aggressive = rng.random(n) < 0.5
    got = carried_others(ARRAY, l1_x, l1_v, l1_decel, f_x, f_v, aggressive, prm.a_x_a, prm.a_x_d, delay)
    want_l1 = _worst_by_hand(l1_x, l1_v, -l1_decel, delay)
    want_f = _worst_by_hand(f_x, f_v, np.where(aggressive, prm.a_x_a, -prm.a_x_d), delay)
    np.testing.assert_allclose(np.array(got[:2]), want_l1, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.array(got[2:]), want_f, rtol=1e-12, atol=1e-12)
    assert (want_f[1][~aggressive] == 0.0).any() and (want_l1[1] == 0.0).any()  # some stop inside the delay
