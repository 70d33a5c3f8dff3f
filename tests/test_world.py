"""The world model (safelane.shield.world): other vehicles folded into F, the chain and the own lane.

Each rule against a hand computation written here (not the module's formulas): the lanes a vehicle's body overlaps,
the RSS lateral worst case's reach (accelerate toward the lane for ρ, then brake laterally to zero lateral speed, plus
μ/2), a connected vehicle's announcement window, F replaced by a nearer entrant, the connected chain cut at the first
non-connected entrant, padding, validation errors, and the fold inside the shield's first stage."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from safelane import Params
from safelane.baselines.rss import RssParams
from safelane.shield import ShieldConfig, Situation, core
from safelane.shield.decide import PROCEED
from safelane.shield.situation import SensingBounds
from safelane.shield.world import ANNOUNCE_HORIZON_S, NO_LANE, Others, fold, follower_switched, lane_reach, roles

PRM = Params(lane_width=4.0, vehicle_width=2.0, vehicle_length=5.0, a_x_a=3.0)  # highway-env's geometry
W, WV = PRM.lane_width, PRM.vehicle_width
RSS = RssParams.matched(PRM)  # rho = 0.1 s, lateral accel = lateral brake = a_y_m = 1.5 m/s², mu = 0.1 m


def situation(others=None, *, ego_y=1.0, follower=(-30.0, 25.0), leaders=((40.0, 60.0, 80.0), (25.0, 25.0, 25.0)),
              n=2, own=None, t=0.0, **kw):  # fmt: skip
    extra = {} if own is None else {"own_leaders": own, "own_n_connected": 0}
    return Situation.from_arrays(t=t, ego=(0.0, ego_y, 25.0, 0.0), follower=follower, leaders=leaders, n_connected=n,
                                 promise_decel=[[0.5, 1.0]], params=PRM, others=others, **extra, **kw)  # fmt: skip


def one(x, y, vx=25.0, vy=0.0, **kw):
    return Others.from_arrays([[x]], [[y]], [[vx]], [[vy]], **kw)


def reach_by_hand(v_toward: float) -> float:
    """RSS's lateral offset toward a lane, written out: a·ρ²/2 + v·ρ, then (v + a·ρ)²/(2b) if still moving toward it."""
    rho, a, b = 0.1, 1.5, 1.5
    v_r = v_toward + a * rho
    return 0.5 * a * rho * rho + v_toward * rho + (v_r * v_r / (2 * b) if v_r > 0 else 0.0)


def threshold_speed(gap: float) -> float:
    """The lateral speed whose reach is exactly ``gap``: u = v + a·ρ solves u²/(2b) + ρ·u − a·ρ²/2 = gap."""
    rho, a, b = 0.1, 1.5, 1.5
    qa, qb, qc = 1 / (2 * b), rho, -(0.5 * a * rho * rho) - gap
    u = (-qb + math.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
    return u - a * rho


def stop_by_hand(v: float) -> float:
    """RSS's stopping distance of the ego as the rear vehicle, written out: a_x_a for ρ = dt, then a_x_d to rest."""
    rho, up, dn = PRM.dt, PRM.a_x_a, PRM.a_x_d
    return v * rho + 0.5 * up * rho * rho + (v + up * rho) ** 2 / (2 * dn)


def entry_gap_by_hand(v_front: float, v_rear: float) -> float:
    """The centre distance an entrant must leave ahead of the ego: p_m plus RSS's distance (a_o_d = a_x_d here, so
    RSS's closed form is exact: the rear's stopping distance less the front's braking distance, at least 0)."""
    return PRM.p_m + max(0.0, stop_by_hand(v_rear) - v_front**2 / (2 * PRM.others_decel))


def dilemma_by_hand(y: float, vy: float) -> float:
    """One period of a_y_m toward the target lane, then the fastest return to y_s = (w_l − w_v)/2 with zero lateral
    speed (stop the lateral motion, then half the way at −a_y_m and half at +a_y_m), plus one period."""
    a, dt, y_s = PRM.a_y_m, PRM.dt, 0.5 * (W - WV)
    y1, v1 = y + vy * dt + 0.5 * a * dt * dt, vy + a * dt
    peak = y1 + v1 * v1 / (2 * a)
    return v1 / a + 2 * math.sqrt((peak - y_s) / a) + dt


def combined_by_hand(*vehicles) -> tuple[float, float]:
    """The slot several vehicles that may be there are folded into: the nearest position, and the speed whose braking
    at a_o_d stops at the nearest of their stopping points (each (x, v) braking at a_o_d)."""
    a = PRM.others_decel
    x = min(xv[0] for xv in vehicles)
    stop = min(xv[0] + xv[1] ** 2 / (2 * a) for xv in vehicles)
    return x, math.sqrt(2 * a * (stop - x))


def test_the_combined_slot_brakes_behind_each_vehicle_at_every_instant():
    """The hand rule above, checked on a time grid against each vehicle's own braking (not a formula of the module):
    the combined trajectory is never ahead of any of them."""
    a, t = PRM.others_decel, np.linspace(0.0, 8.0, 8001)

    def braking(x, v):
        tt = np.minimum(t, v / a)
        return x + v * tt - 0.5 * a * tt * tt

    rng = np.random.default_rng(0)
    for _ in range(200):
        cars = [(float(rng.uniform(0, 60)), float(rng.uniform(0, 35))) for _ in range(3)]
        low = braking(*combined_by_hand(*cars))
        assert all((low <= braking(*car) + 1e-9).all() for car in cars), cars


def test_rss_matched_parameters_are_the_ones_the_hand_computation_uses():
    assert (RSS.response_time_other, RSS.lat_accel_max, RSS.lat_brake_min) == (0.1, 1.5, 1.5)
    assert RSS.lateral_fluctuation_margin == pytest.approx(0.1)


def test_a_straddler_counts_in_both_lanes_and_takes_both_roles():
    # centre on the lane line y = w/2: its body [1, 3] overlaps lane 0 [-2, 2] and lane 1 [2, 6]
    s = situation(one(20.0, 0.5 * W, vx=22.0, connected=True))
    inside = lane_reach(s.others, 0.0, PRM)
    assert inside.tolist() == [[[True, True]]]
    r = roles(s, PRM)
    assert r.chain_x[0, 0] == 20.0 and r.chain_v[0, 0] == 22.0 and r.n_connected[0] == 0  # L1, ends the chain
    assert r.own_x.tolist() == [[20.0]] and r.own_v.tolist() == [[22.0]] and r.own_n_connected[0] == 0  # L0
    assert r.others is None


def test_a_connected_vehicle_just_inside_its_lane_counts_only_there():
    # lane 2's vehicle whose body edge lies 1 mm beyond the boundary 1.5 w: connected, no reach
    y = 1.5 * W + 0.5 * WV + 1e-3
    assert lane_reach(one(20.0, y, vy=-3.0, connected=True), 0.0, PRM).tolist() == [[[False, False]]]
    # its body over the line by 1 mm: it counts in the target lane
    y = 1.5 * W + 0.5 * WV - 1e-3
    assert lane_reach(one(20.0, y, connected=True), 0.0, PRM).tolist() == [[[False, True]]]


@pytest.mark.parametrize("side", [+1, -1])
def test_far_lane_vehicle_counts_once_its_lateral_worst_case_reaches_the_lane(side):
    """Lane 2 (side +1: beyond the target lane, entering it) or lane −1 (side −1: the ego's other side, entering the
    ego's lane): centred in its lane, moving toward the ego's lanes at v_y. In lane −1 the reach puts it into L0 at its
    own state; below the threshold rule 4 still counts it, at the cut-in bound (the test below). In lane 2 the reach
    decides for a vehicle behind the ego (ahead of it, rule 5 counts it anyway), which becomes F, nearer than F at
    −30 m."""
    lane = 2 if side > 0 else -1
    role_lane = 1 if side > 0 else 0
    y = lane * W
    gap = 0.5 * W - 0.5 * WV - 0.5 * 0.1  # body edge to the lane line, minus mu/2: 0.95 m
    v_star = threshold_speed(gap)
    assert reach_by_hand(v_star) == pytest.approx(gap, abs=1e-12)
    for v, counted in ((v_star - 1e-3, False), (v_star + 1e-3, True), (0.0, False), (-2.0, False)):
        x = -12.0 if side > 0 else 20.0
        o = one(x, y, vx=15.0, vy=-side * v)
        inside = lane_reach(o, 0.0, PRM)[0, 0]
        assert inside[role_lane] == counted and inside[1 - role_lane] is np.False_, (v, inside)
        r = roles(situation(o), PRM)
        if side > 0:  # the entrant behind the ego becomes F: 12 m behind, nearer than F at 30 m
            assert (r.f_x[0] == -12.0) == counted
            assert r.n_connected[0] == 2 and r.chain_x[0, 0] == 40.0
        else:  # counted by its reach: L0 at its own state; otherwise rule 4's cut-in bound p_m ahead of the ego
            assert r.own_x[0, 0] == (20.0 if counted else PRM.p_m), (v, r.own_x)


def test_a_vehicle_in_the_lane_beside_the_egos_counts_in_it():
    """Rule 4, found by the multi-lane falsifier twice: a vehicle beside the ego's lane may enter it ahead of the ego at
    RSS's distance while the ego escapes an aggressive F and cannot brake. A non-connected vehicle whose body is in
    lane −1 counts in lane 0 (virtually: it hides no L0 ahead of it): at its own state once it is at the entry
    distance; before that, if it can reach p_m ahead of the ego within the dilemma (it at a_x_a, the ego braking at
    a_x_d), at the cut-in bound (ego_x + p_m, v*), v*² = 2·a_o_d·(the ego's RSS stopping distance); otherwise not at
    all. All by hand: lane −1 spans y in (−1.5·W, −0.5·W), a body overlaps it while its centre is in
    (−1.5·W − WV/2, −0.5·W + WV/2); the ego is at x = 0, 25 m/s, y = 1 (the situation helper)."""
    ego_v, h = 25.0, dilemma_by_hand(1.0, 0.0)
    cut = (PRM.p_m, math.sqrt(2 * PRM.others_decel * stop_by_hand(ego_v)))

    def own(r):
        return None if r.own_x is None or not np.isfinite(r.own_x[0, 0]) else (r.own_x[0, 0], r.own_v[0, 0])

    ready = entry_gap_by_hand(15.0, ego_v)  # 15 m/s: a slower vehicle must leave more than p_m
    lo, hi = -1.5 * W - 0.5 * WV, -0.5 * W + 0.5 * WV
    for y, beside in ((hi - 1e-6, True), (lo + 1e-6, True), (lo - 1e-3, False), (-W, True)):
        assert (own(roles(situation(one(ready + 1.0, y, vx=15.0)), PRM)) is not None) == beside, y
    assert own(roles(situation(one(ready + 1.0, -W, vx=15.0, connected=True)), PRM)) is None  # it announces
    # at the entry distance: its own state; 1 mm short of it: the cut-in bound
    assert own(roles(situation(one(ready + 1e-3, -W, vx=15.0)), PRM)) == pytest.approx((ready + 1e-3, 15.0))
    assert own(roles(situation(one(ready - 1e-3, -W, vx=15.0)), PRM)) == pytest.approx(cut)
    # behind the ego: the cut-in bound while it can reach p_m ahead within the dilemma, no role beyond
    gained = 30.0 * h + 0.5 * PRM.a_x_a * h * h - (ego_v * h - 0.5 * PRM.a_x_d * h * h)  # the ego does not stop
    assert ego_v / PRM.a_x_d > h
    reach_x = PRM.p_m - gained
    assert own(roles(situation(one(reach_x + 1e-3, -W, vx=30.0)), PRM)) == pytest.approx(cut)
    assert own(roles(situation(one(reach_x - 1e-3, -W, vx=30.0)), PRM)) is None
    # a longer dilemma (the ego deeper in the target lane, moving toward it) reaches farther back
    deep = roles(situation(one(reach_x - 5.0, -W, vx=30.0), ego_y=2.5), PRM)
    assert dilemma_by_hand(2.5, 0.0) > h and own(deep) == pytest.approx(cut)
    # virtual: L0 physically ahead is not hidden; the slot takes the combined stopping point (by hand)
    l0 = ([[36.0, np.inf]], [[10.0, 0.0]])
    r = roles(situation(one(ready - 1e-3, -W, vx=15.0), own=l0), PRM)
    assert own(r) == pytest.approx(combined_by_hand(cut, (36.0, 10.0)))
    assert r.own_v[0, 0] < cut[1]  # the slower L0 binds


def test_far_lane_vehicle_behind_becomes_f_when_its_reach_crosses_and_not_before():
    """A lane-2 vehicle behind the ego whose lateral speed toward the target lane grows by 0.3 m/s each period (its
    position fixed, as if sampled at the period's start): F from the first period whose speed is above the hand
    threshold."""
    v_star = threshold_speed(0.5 * W - 0.5 * WV - 0.05)
    speeds = 0.3 * np.arange(12)
    first = int(np.argmax(speeds > v_star))
    for k, v in enumerate(speeds):
        r = roles(situation(one(-12.0, 2 * W, vx=15.0, vy=-v)), PRM)
        assert (r.f_x[0] == -12.0) == (k >= first), (k, v)


def test_a_vehicle_beyond_the_target_lane_counts_in_it_as_rule_4_counts_one_beside():
    """Rule 5, found by the multi-lane falsifier: a vehicle in lane 2 may enter the target lane ahead of a straddling
    ego at RSS's distance and brake while the ego's evasion accelerates away from an aggressive F. It counts in the
    target lane as rule 4's vehicle counts in lane 0 — its own state at the entry distance, the cut-in bound before,
    no role where it cannot get ahead within the dilemma — whatever its lateral speed, and virtually (L1 is not
    hidden). By hand: lane 2 spans y in (1.5·W, 2.5·W); a body overlaps it while its centre is in
    (1.5·W − WV/2, 2.5·W + WV/2)."""
    ego_v, h = 25.0, dilemma_by_hand(1.0, 0.0)
    cut = (PRM.p_m, math.sqrt(2 * PRM.others_decel * stop_by_hand(ego_v)))
    ready = entry_gap_by_hand(28.0, ego_v)
    assert ready < 20.0
    lo, hi = 1.5 * W - 0.5 * WV, 2.5 * W + 0.5 * WV
    for y, beyond in ((lo + 1e-6, True), (hi - 1e-6, True), (hi + 1e-3, False), (2 * W, True)):
        for vy in (0.0, 1.0):  # moving away from the target lane too
            r = roles(situation(one(20.0, y, vx=28.0, vy=vy), leaders=((60.0, 80.0, 100.0), (28.0, 28.0, 28.0))),
                      PRM)  # fmt: skip
            assert (r.chain_x[0, 0] == 20.0) == beyond, (y, vy)
            assert r.n_connected[0] == (0 if beyond else 2)
    assert roles(situation(one(20.0, 2 * W, vx=15.0, connected=True)), PRM).chain_x[0, 0] == 40.0  # it announces
    short = roles(situation(one(ready - 1e-3, 2 * W, vx=28.0)), PRM)  # 1 mm short of the entry distance
    assert (short.chain_x[0, 0], short.n_connected[0]) == (PRM.p_m, 0)
    assert short.chain_v[0, 0] == pytest.approx(combined_by_hand(cut, (40.0, 25.0))[1])  # L1 (40 m, 25 m/s) folded in
    gained = 30.0 * h + 0.5 * PRM.a_x_a * h * h - (ego_v * h - 0.5 * PRM.a_x_d * h * h)
    reach_x = PRM.p_m - gained
    assert roles(situation(one(reach_x + 1e-3, 2 * W, vx=30.0)), PRM).chain_x[0, 0] == PRM.p_m  # behind, can reach
    behind = roles(situation(one(reach_x - 1e-3, 2 * W, vx=30.0)), PRM)  # cannot: no role (not F either)
    assert behind.chain_x[0, 0] == 40.0 and behind.f_x[0] == -30.0
    r = roles(situation(one(30.0, 2 * W, vx=28.0)), PRM)  # at the entry distance; L1 (40 m, 25 m/s) not hidden
    assert (r.chain_x[0, 0], r.chain_v[0, 0]) == pytest.approx(combined_by_hand((30.0, 28.0), (40.0, 25.0)))
    r = roles(situation(one(30.0, 2 * W, vx=28.0), leaders=((40.0, 60.0, 80.0), (10.0, 25.0, 25.0))), PRM)
    expected = combined_by_hand((30.0, 28.0), (40.0, 10.0))[1]
    assert r.chain_v[0, 0] == pytest.approx(expected) and expected < 28.0  # a slow L1 binds


def test_connected_announcement_counts_from_announce_t_minus_horizon():
    h = ANNOUNCE_HORIZON_S
    o = one(20.0, 2 * W, vy=-1.0, connected=True, announce_lane=1, announce_t=12.0)  # lane 2 -> lane 1 at 12 s
    before, at = 12.0 - h - 0.05, 12.0 - h
    assert lane_reach(o, before, PRM)[0, 0].tolist() == [False, False]  # trusted: no reach, not yet announced
    assert lane_reach(o, at, PRM)[0, 0].tolist() == [False, True]
    assert lane_reach(o, 30.0, PRM)[0, 0].tolist() == [False, True]  # the announcement stands
    assert roles(situation(o, t=before), PRM).chain_x[0, 0] == 40.0
    assert roles(situation(o, t=at), PRM).chain_x[0, 0] == 20.0
    # announced into the ego's lane (0): L0 from then on
    o0 = one(20.0, -W, connected=True, announce_lane=0, announce_t=3.0)
    assert roles(situation(o0, t=3.0 - h), PRM).own_x[0, 0] == 20.0
    assert roles(situation(o0, t=3.0 - h - 0.1), PRM).own_x is None
    # the same vehicle, not connected, moving 1 m/s toward lane 1 from lane 2: reach 0.0075+0.1+1.15²/3 = 0.548 m
    # < 0.95 m, so it does not count either
    assert lane_reach(one(20.0, 2 * W, vy=-1.0), 0.0, PRM)[0, 0].tolist() == [False, False]


def test_f_is_replaced_by_a_nearer_entrant_behind_and_taken_as_non_connected():
    s = situation(one(-12.0, W, vx=28.0), f_connected=True, f_collaborative=True)
    r = roles(s, PRM)
    assert (r.f_x[0], r.f_v[0]) == (-12.0, 28.0)
    assert not r.f_connected[0] and not r.f_collaborative[0]
    # farther than F: F stays, with its V2X status
    r2 = roles(situation(one(-45.0, W, vx=28.0), f_connected=True, f_collaborative=True), PRM)
    assert (r2.f_x[0], r2.f_v[0], bool(r2.f_connected[0]), bool(r2.f_collaborative[0])) == (-30.0, 25.0, True, True)


def test_n_shrinks_at_the_first_non_connected_entrant():
    # chain L1 40, L2 60 (connected, promises 0.5, 1.0), L3 80 = L(N+1)
    r = roles(situation(one(50.0, W)), PRM)  # between L1 and L2
    assert r.n_connected[0] == 1
    assert r.chain_x[0, :2].tolist() == [40.0, 50.0] and r.chain_v[0, :2].tolist() == [25.0, 25.0]
    assert r.chain_promise[0, 0] == 0.5  # L1's own promise travels with it
    assert r.chain_x[0, 2] > 50.0 + 1000.0  # beyond L(N+1): padding far ahead
    r0 = roles(situation(one(10.0, W)), PRM)  # before L1: it is L1, N = 0
    assert r0.n_connected[0] == 0 and r0.chain_x[0, 0] == 10.0
    r_far = roles(situation(one(90.0, W)), PRM)  # beyond L(N+1): nothing changes that the analysis reads
    assert r_far.n_connected[0] == 2 and r_far.chain_x[0].tolist() == [40.0, 60.0, 80.0]
    r_two = roles(situation(Others.from_arrays([[70.0, 45.0]], [[W, W]], [[20.0, 21.0]], [[0.0, 0.0]])), PRM)
    assert r_two.n_connected[0] == 1 and r_two.chain_x[0, :2].tolist() == [40.0, 45.0]
    assert r_two.chain_v[0, 1] == 21.0
    r_two.validate(PRM)


def test_own_lane_merge_keeps_l0_first():
    own = ([[30.0, np.inf]], [[20.0, 0.0]])
    r = roles(situation(one(15.0, 0.0, vx=18.0), own=own), PRM)  # an own-lane vehicle ahead of L0
    assert r.own_x[0].tolist() == [15.0, np.inf] and r.own_v[0, 0] == 18.0 and r.own_n_connected[0] == 0
    r2 = roles(situation(one(50.0, 0.0), own=own), PRM)  # ahead of L0 (non-connected): L0 stays
    assert r2.own_x[0].tolist() == [30.0, np.inf]
    r3 = roles(situation(one(-5.0, 0.0), own=own), PRM)  # behind the ego in its lane: no role
    assert r3.own_x[0].tolist() == [30.0, np.inf] and r3.f_x[0] == -30.0
    r.validate(PRM)


def test_a_vehicle_counted_by_reach_or_announcement_alone_hides_no_vehicle_ahead():
    """Found by the multi-lane falsifier: a vehicle in the lane beside, counted in the ego's lane by its announcement
    (or its reach) but not in it, was merged as L0 and the slower, physically present L0 ahead of it was dropped.
    The slot now combines them (the nearest position, and the speed braking to the nearer stopping point; checked
    against each vehicle's braking on a time grid above): a slower L0 ahead binds, a faster one does not."""
    own = ([[36.0, np.inf]], [[20.0, 0.0]])
    announced = one(24.0, -W, vx=30.8, connected=True, announce_lane=0, announce_t=0.0)  # lane -1, announced lane 0
    r = roles(situation(announced, own=own), PRM)
    assert r.own_x[0, 0] == 24.0 and r.own_n_connected[0] == 0
    expected = combined_by_hand((24.0, 30.8), (36.0, 20.0))[1]
    assert r.own_v[0, 0] == pytest.approx(expected) and expected < 30.8
    assert roles(situation(announced, own=([[36.0, np.inf]], [[29.5, 0.0]])), PRM).own_v[0, 0] == 30.8  # L0 ahead
    inside = one(24.0, 0.0, vx=30.8)  # physically in the ego's lane: it shields L0, as before
    assert roles(situation(inside, own=own), PRM).own_v[0, 0] == 30.8
    # the target lane: an announced entrant nearer than L1 (connected, 25 m/s) folds L1 in, N = 0
    fast = one(30.0, 2 * W, vx=28.0, connected=True, announce_lane=1, announce_t=0.0)
    rc = roles(situation(fast), PRM)
    assert rc.chain_x[0, 0] == 30.0 and rc.n_connected[0] == 0
    assert rc.chain_v[0, 0] == pytest.approx(combined_by_hand((30.0, 28.0), (40.0, 25.0))[1])
    assert roles(situation(one(30.0, W, vx=28.0)), PRM).chain_v[0, 0] == 28.0  # physically there
    # behind: an announced entrant nearer than F but slower takes F's higher speed (F's worst case is ahead of both)
    slow = one(-20.0, 2 * W, vx=20.0, connected=True, announce_lane=1, announce_t=0.0)
    rf = roles(situation(slow), PRM)
    assert (rf.f_x[0], rf.f_v[0]) == (-20.0, 25.0)
    assert (roles(situation(one(-20.0, W, vx=20.0)), PRM).f_v[0]) == 20.0  # physically there: it is F
    for folded in (r, rc, rf):
        folded.validate(PRM)


def test_an_f_that_is_not_last_periods_vehicle_restarts_the_assessment():
    """Found by the multi-lane falsifier: F went back from a nearer entrant (counted by its reach) to the host's F;
    the assessment read the drop in speed as F yielding. A period's reachable set by hand: from (x, v), at most
    x + v·dt + a_x_a·dt²/2 and v + a_x_a·dt, at least x + v·dt − a_o_d·dt²/2 and v − a_o_d·dt."""
    from types import SimpleNamespace

    dt, a_up, a_down = PRM.dt, PRM.a_x_a, PRM.others_decel
    last = SimpleNamespace(f_x=np.array([-30.0, -30.0, -30.0, -30.0]), f_v=np.full(4, 25.0))
    x_top = -30.0 + 25.0 * dt + 0.5 * a_up * dt * dt
    x_bottom = -30.0 + 25.0 * dt - 0.5 * a_down * dt * dt
    now = SimpleNamespace(f_x=np.array([x_top - 1e-6, x_top + 1e-3, x_bottom + 1e-6, x_top - 1e-6]),
                          f_v=np.array([25.0 + a_up * dt, 25.0, 25.0 - a_down * dt, 25.0 - a_down * dt - 0.5]),
                          err_f=None)  # fmt: skip
    assert follower_switched(last, now, PRM).tolist() == [False, True, False, True]
    assert not follower_switched(None, now, PRM).any()
    # in the shield: a state whose last F was 36 m/s, now 33: the belief restarts (aggressive)
    s = situation(Others.empty(1, 1), follower=(-25.0, 33.0))
    state = core.init(situation(follower=(-25.0 - 3.6, 36.0)), PRM, ShieldConfig())
    state = dataclasses.replace(state, last=SimpleNamespace(f_x=np.array([-25.0 - 3.6]), f_v=np.array([36.0])))
    belief = dataclasses.replace(state.belief, aggressive=np.array([False]))
    state = dataclasses.replace(state, belief=belief)
    restarted, _, _ = fold(state, s, PRM, ShieldConfig())
    assert restarted.belief.aggressive.tolist() == [True]


def test_padding_and_vehicles_without_a_role_change_nothing():
    s = situation()
    pad = Others.empty(1, 3)
    far = Others.from_arrays([[np.inf, -20.0, -10.0]], [[0.0, 2 * W, 0.0]], [[0.0, 25.0, 25.0]], [[0.0, 0.0, 0.5]])
    for o in (pad, far):  # padding; lane 2 behind the ego, at rest laterally; own lane behind the ego
        r = roles(dataclasses.replace(s, others=o), PRM)
        for f in dataclasses.fields(Situation):
            a, b = getattr(r, f.name), getattr(s, f.name)
            assert (a is None and b is None) or np.array_equal(a, b), f.name
    assert roles(s, PRM) is s  # no others: the situation as it is


def test_rows_are_independent():
    rng = np.random.default_rng(7)
    b, k = 40, 6
    x = rng.uniform(-60, 100, (b, k))
    x[rng.random((b, k)) < 0.2] = np.inf
    others = Others.from_arrays(x, rng.uniform(-W, 2.5 * W, (b, k)), rng.uniform(10, 30, (b, k)),
                                rng.uniform(-2, 2, (b, k)))  # fmt: skip
    lead = np.sort(rng.uniform(15, 120, (b, 3)), axis=1)
    s = Situation.from_arrays(t=0.0, ego=(np.zeros(b), rng.uniform(0, W, b), np.full(b, 25.0), np.zeros(b)),
                              follower=(rng.uniform(-50, -8, b), np.full(b, 25.0)),
                              leaders=(lead, np.full((b, 3), 25.0)), n_connected=rng.integers(0, 3, b),
                              own_leaders=(rng.uniform(10, 80, (b, 1)), np.full((b, 1), 20.0)), params=PRM,
                              others=others, sensing=SensingBounds(), geometry="ignore")  # fmt: skip
    whole = roles(s, PRM)
    whole.validate(PRM)
    for i in range(b):
        row = roles(take_row(s, i), PRM)
        for f in dataclasses.fields(Situation):
            a, c = getattr(whole, f.name), getattr(row, f.name)
            if f.name in ("t", "others") or a is None:
                continue
            assert np.array_equal(np.asarray(a)[i], np.asarray(c)[0]), (i, f.name)


def take_row(s, i):
    out = {}
    for f in dataclasses.fields(Situation):
        a = getattr(s, f.name)
        if f.name == "t" or a is None:
            out[f.name] = a
        elif f.name == "others":
            out[f.name] = Others(*(np.asarray(q)[i : i + 1] for q in dataclasses.astuple(a)))
        else:
            out[f.name] = np.asarray(a)[i : i + 1]
    return Situation(**out)


def test_inserted_vehicles_take_the_loosest_sensing_bound_of_their_row():
    s = situation(one(50.0, W), sensing=SensingBounds(connected_pos_m=0.3, sensed_pos_m=1.2, sensed_speed_mps=0.7))
    r = roles(s, PRM)
    assert r.err_chain[0, 1].tolist() == [1.2, 0.7]  # the entrant, after L1
    assert r.err_chain[0, 0].tolist() == [0.3, 0.2]  # L1 keeps its own


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(x=np.array([[np.nan]])), r"others\.x\[0, 0\] must be finite, or \+inf for padding; got nan"),
        (dict(x=np.array([[-np.inf]])), r"others\.x\[0, 0\] must be finite.*got -inf"),
        (dict(vx=np.array([[-1.0]])), r"others\.vx\[0, 0\] must be >= 0.*got -1\.0"),
        (dict(y=np.array([[np.inf]])), r"others\.y\[0, 0\] must be finite; got inf"),
        (dict(connected=np.array([[1]])), r"others\.connected must be booleans"),
        (dict(announce_lane=np.array([[1]])), r"others\.announce_lane\[0, 0\] must be .*NO_LANE.*not connected"),
        (dict(announce_lane=np.array([[1.0]])), r"others\.announce_lane must be integers"),
        (dict(vy=np.zeros((1, 2))), r"others\.vy must have shape \(1, 1\); got \(1, 2\)"),
    ],
)
def test_validation_names_field_slot_and_value(change, message):
    o = dataclasses.replace(one(20.0, W), **change)
    with pytest.raises(ValueError, match=message):
        situation(o)


def test_validation_of_announcements_and_batch():
    o = one(20.0, 2 * W, connected=True, announce_lane=1, announce_t=np.nan)
    with pytest.raises(ValueError, match=r"others\.announce_t\[0, 0\] must be finite where a lane change is announced"):
        situation(o)
    with pytest.raises(ValueError, match=r"others\.x must have shape \(1, K\)"):
        dataclasses.replace(situation(), others=Others.empty(2, 1)).validate(PRM)
    with pytest.raises(ValueError, match=r"Situation\.others must be a safelane\.shield\.world\.Others"):
        dataclasses.replace(situation(), others=(1, 2)).validate(PRM)
    assert one(20.0, W).announce_lane[0, 0] == NO_LANE


def test_from_arrays_maps_a_tuple_through_the_frame():
    from safelane.shield import LaneFrame

    frame = LaneFrame(origin_y=8.0, sign=-1.0)  # highway-env: target lane to the left (smaller y)
    s = Situation.from_arrays(t=0.0, ego=(0.0, 8.0, 25.0, 0.0), follower=(-30.0, 25.0), leaders=([40.0], [25.0]),
                              n_connected=0, frame=frame, params=PRM,
                              others=([[20.0]], [[0.0]], [[25.0]], [[0.5]]))  # fmt: skip
    assert s.others.y.tolist() == [[8.0]] and s.others.vy.tolist() == [[-0.5]]  # lane 2 in the shield's frame


def test_fold_restarts_the_assessment_where_f_was_replaced():
    cfg = ShieldConfig()
    s = situation(one(-12.0, W, vx=28.0))
    state = core.init(roles(s, PRM), PRM, cfg, "CV_all")
    belief = dataclasses.replace(state.belief, aggressive=np.array([False]), count=np.array([9]))
    state = dataclasses.replace(state, belief=belief)
    new_state, folded, chain = fold(state, s, PRM, cfg, chain="unused")
    assert chain is None and folded.f_x[0] == -12.0
    assert new_state.belief.aggressive.tolist() == [True] and new_state.belief.count.tolist() == [0]
    # without others: the very objects back
    bare = dataclasses.replace(s, others=None)
    assert fold(state, bare, PRM, cfg, "chain") == (state, bare, "chain")


def test_the_shields_first_stage_folds_the_others():
    """Straddling at y = 2 m: a lane-2 vehicle moving toward the target lane fast enough to count, 6 m behind at
    20 m/s (too slow to get ahead of the ego within the dilemma, so rule 5 leaves it out), ends the lane change's safe
    evasion; below the threshold speed it changes nothing (bit-identical decision)."""
    v_star = threshold_speed(0.5 * W - 0.5 * WV - 0.05)
    proposal = (np.array([0.0]), np.array([1.0]))
    decisions = {}
    for name, vy in (("none", None), ("slow", v_star - 0.01), ("fast", v_star + 0.01)):
        o = None if vy is None else one(-6.0, 2 * W, vx=20.0, vy=-vy)
        s = situation(o, ego_y=2.0)
        state = core.init(roles(s, PRM), PRM, ShieldConfig(), "CV_all")
        decisions[name] = core.step(state, s, proposal, PRM, ShieldConfig(), "CV_all")[1]
    assert decisions["none"].behaviour[0] == PROCEED
    for field in ("behaviour", "a_x", "a_y", "l1_decel"):
        assert np.array_equal(getattr(decisions["slow"], field), getattr(decisions["none"], field)), field
    assert decisions["fast"].behaviour[0] != PROCEED


def test_init_and_observe_fold_the_others_as_every_period_does():
    """The plan held at the start and the monitor's last look take the others' roles: init with ``others`` is init on
    the folded situation, field by field (an entrant 9 m ahead in the target lane changes the starting plan)."""
    s = situation(one(9.0, 1.0 * W, vx=20.0), ego_y=1.0)
    folded = roles(s, PRM)
    with_others, by_hand = core.init(s, PRM, ShieldConfig()), core.init(folded, PRM, ShieldConfig())
    without = core.init(dataclasses.replace(s, others=None), PRM, ShieldConfig())
    for f in dataclasses.fields(with_others.plan):
        if f.name != "params":
            a, b = getattr(with_others.plan, f.name), getattr(by_hand.plan, f.name)
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f.name
    assert not np.array_equal(with_others.plan.l1_p, without.plan.l1_p)  # the entrant is the plan's L1
    state, _ = core.step(with_others, s, (np.zeros(1), np.zeros(1)), PRM)
    later = dataclasses.replace(s, t=s.t + PRM.dt)
    assert np.array_equal(core.observe(state, later, PRM).breach.flags, core.observe(state, roles(later, PRM),
                                                                                  PRM).breach.flags)
