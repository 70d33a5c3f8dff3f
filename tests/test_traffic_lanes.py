"""Traffic-level co-simulation (safelane.traffic, docs/traffic.md) without SUMO: a vehicle across a lane boundary
counts in both lanes (the measures' cut-in rule, the changers' situation), a missing F or L1 does not pull the
expert, and an aborted lane change returns to its own lane within the deadline (a kinematic stand-in for the SUMO
world drives the other vehicles)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.traffic import measures
from safelane.traffic.demand import LANE_W, lane_of, lane_y
from safelane.traffic.equipped import BRAKE_COMFORT, LaneChanges

PRM = Params()
STRADDLE = 1.9  # [m] a centre this far from its lane's centre is across the boundary, its body still in the lane


def fleet(rows):
    """A fleet from ``(id, x, y, v)`` rows (lane from ``y``, equipped by the id)."""
    ids, x, y, v = zip(*rows, strict=True)
    y = np.array(y, float)
    return SimpleNamespace(ids=tuple(ids), x=np.array(x, float), y=y, v=np.array(v, float), a=np.zeros(len(ids)),
                           lane=lane_of(y), equipped=np.array([i.startswith("cav.") for i in ids]))  # fmt: skip


# -- the measures
def test_a_vehicle_across_a_lane_boundary_is_in_both_lanes():
    f = fleet([("cav.s", 0.0, lane_y(1) + STRADDLE, 20.0), ("human.a", 0.0, lane_y(1) + 0.5, 20.0),
               ("human.b", 0.0, lane_y(2), 20.0)])  # fmt: skip
    over = measures.lanes_overlapped(f, PRM.vehicle_width)
    assert lane_of(lane_y(1) + STRADDLE) == 0  # its centre is on lane 0's side ...
    assert over[0].tolist() == [True, True, False, False]  # ... and it is in lanes 0 and 1
    assert over[1].tolist() == [False, True, False, False] and over[2].tolist() == [False, False, True, False]
    # the body's edge on the line is not yet across it
    edge = 0.5 * (LANE_W - PRM.vehicle_width)
    touching = fleet([("cav.t", 0.0, lane_y(1) + edge, 20.0)])
    assert measures.lanes_overlapped(touching, PRM.vehicle_width)[0].tolist() == [False, True, False, False]


def test_a_human_cutting_in_front_of_a_straddling_vehicle_is_responsible():
    """The p = 0.75 sweep cell's case: ``cav.s`` straddles lanes 1 and 0 with its centre on lane 0's side; a human
    changes from lane 2 into lane 1 0.5 m in front of its bumper, and ``cav.s`` runs into it."""
    prev: dict[str, int] = {}
    before = fleet([("cav.s", 100.0, lane_y(1) + STRADDLE, 23.5), ("human.c", 105.3, lane_y(2), 21.2),
                    ("human.far", 40.0, lane_y(1), 25.0)])  # fmt: skip
    assert measures.lane_entries(140.0, before, prev, PRM.vehicle_length, PRM.vehicle_width) == []
    after = fleet([("cav.s", 102.3, lane_y(1) + STRADDLE, 23.5), ("human.c", 107.4, lane_y(1), 21.2),
                   ("human.far", 42.5, lane_y(1), 25.0)])  # fmt: skip
    entries = measures.lane_entries(140.1, after, prev, PRM.vehicle_length, PRM.vehicle_width)
    assert [(e["vid"], e["lane"], e["follower"]) for e in entries] == [("human.c", 1, "cav.s")]
    assert entries[0]["gap_m"] == pytest.approx(107.4 - 102.3 - PRM.vehicle_length)
    crash = {"t": 140.7, "collider": "cav.s", "victim": "human.c", "type": "collision"}
    judged = measures.blame([crash], entries)[0]
    assert (judged["responsible"], judged["rule"]) == ("human.c", "cut-in")
    # by centres alone (the rule before): the follower in lane 1 would be human.far, and cav.s responsible
    by_centre = [{**entries[0], "follower": "human.far"}]
    assert measures.blame([crash], by_centre)[0]["responsible"] == "cav.s"


def test_a_changer_enters_the_target_lane_when_its_body_crosses_the_line():
    prev: dict[str, int] = {}
    edge = 0.5 * (LANE_W - PRM.vehicle_width)
    ys = [lane_y(1), lane_y(1) + edge - 0.01, lane_y(1) + edge + 0.05, lane_y(1) + STRADDLE, lane_y(0)]
    seen = []
    for k, y in enumerate(ys):
        f = fleet([("cav.c", 100.0 + k, y, 20.0), ("human.f", 90.0 + k, lane_y(0), 20.0)])
        seen.append(measures.lane_entries(float(k), f, prev, PRM.vehicle_length, PRM.vehicle_width))
    assert [len(e) for e in seen] == [0, 0, 1, 0, 0]  # once, when the body first overlaps lane 0
    assert (seen[2][0]["vid"], seen[2][0]["lane"], seen[2][0]["follower"]) == ("cav.c", 0, "human.f")


# -- the changers' situation
def _changes(ids, g0, sign, ex, ey, v):
    ch = LaneChanges(None, PRM)
    n = len(ids)
    ch.ids, ch.g0, ch.sign = list(ids), np.array(g0, np.int64), np.array(sign, float)
    ch.ex, ch.ey, ch.evx, ch.evy = (np.array(a, float) for a in (ex, ey, v, np.zeros(n)))
    for name, fill in (("t0", 0.0), ("t_done", np.nan), ("t_ret", np.nan), ("t_abort", np.nan)):
        setattr(ch, name, np.full(n, fill))
    ch.aborted, ch.ret, ch.late = (np.zeros(n, bool) for _ in range(3))
    return ch


def test_the_situation_counts_a_straddling_vehicle_in_both_lanes():
    # cav.c in lane 1 changes left (target lane 0); cav.s ahead and cav.b behind straddle lanes 0 and 1 (centres on
    # lane 0's side and on lane 1's side); human.r ahead in lane 2 is in neither
    f = fleet([("cav.c", 100.0, lane_y(1), 25.0), ("cav.s", 130.0, lane_y(1) + STRADDLE, 24.0),
               ("cav.b", 80.0, lane_y(1) + 1.2, 26.0), ("human.r", 110.0, lane_y(2), 22.0),
               ("human.l", 160.0, lane_y(0), 27.0)])  # fmt: skip
    ch = _changes(["cav.c"], [1], [1.0], [100.0], [0.0], [25.0])
    s, chain_ids = ch.situation(f, f.x.copy(), np.array([0]), 0.0)
    assert s.own_x[0, 0] == 130.0 and s.own_v[0, 0] == 24.0  # L0: the straddler, its centre on the other side
    assert (s.chain_x[0, 0], s.chain_x[0, 1]) == (130.0, 160.0)  # L1: the same straddler, then human.l
    assert [f.ids[i] for i in chain_ids[0, :2]] == ["cav.s", "human.l"]
    assert (s.f_x[0], s.f_v[0]) == (80.0, 26.0)  # F: the straddler behind, its centre in lane 1
    assert s.f_connected[0]
    # the same fleet with the straddlers at their lanes' centres: neither is in the target lane any more
    g = fleet([("cav.c", 100.0, lane_y(1), 25.0), ("cav.s", 130.0, lane_y(1), 24.0), ("cav.b", 80.0, lane_y(1), 26.0),
               ("human.r", 110.0, lane_y(2), 22.0), ("human.l", 160.0, lane_y(0), 27.0)])  # fmt: skip
    s2, _ = ch.situation(g, g.x.copy(), np.array([0]), 0.0)
    assert s2.chain_x[0, 0] == 160.0 and s2.f_x[0] < 100.0 - 1e3 and s2.own_x[0, 0] == 130.0


def test_a_missing_follower_or_leader_does_not_pull_the_expert():
    # no F behind in the target lane (the network's start): the expert steered to the middle of a gap 10 km long
    # and braked at a_x_d; now only the speed term acts
    f = fleet([("cav.c", 10.0, lane_y(2), 25.0), ("human.l", 180.0, lane_y(1), 25.0)])
    ch = _changes(["cav.c"], [2], [1.0], [10.0], [0.0], [25.0])
    s, chain_ids = ch.situation(f, f.x.copy(), np.array([0]), 0.0)
    assert s.f_x[0] < -1e3  # the situation pads the missing F far behind (the shield's convention) ...
    a_x, a_y = ch._proposal(s, f, chain_ids, np.zeros(1, bool))
    assert a_x[0] == pytest.approx(0.0, abs=1e-9) and a_y[0] > 0.0  # ... the expert is not pulled back
    # no L1 ahead either: the same
    lone = fleet([("cav.c", 10.0, lane_y(2), 25.0)])
    s, chain_ids = ch.situation(lone, lone.x.copy(), np.array([0]), 0.0)
    assert ch._proposal(s, lone, chain_ids, np.zeros(1, bool))[0][0] == pytest.approx(0.0, abs=1e-9)
    # with both present, the expert's own law (the middle of the gap): F close behind, L1 far ahead -> speed up
    both = fleet([("cav.c", 100.0, lane_y(2), 25.0), ("human.f", 90.0, lane_y(1), 25.0),
                  ("human.l", 200.0, lane_y(1), 25.0)])  # fmt: skip
    ch = _changes(["cav.c"], [2], [1.0], [100.0], [0.0], [25.0])
    s, chain_ids = ch.situation(both, both.x.copy(), np.array([0]), 0.0)
    assert ch._proposal(s, both, chain_ids, np.zeros(1, bool))[0][0] == pytest.approx(PRM.a_x_a)


def test_the_expert_brakes_comfortably_and_keeps_its_own_lanes_leader_ahead():
    # F 40 m behind, L1 10 m ahead and slower: the gap's middle is 15 m behind -> the expert brakes
    gap = fleet([("cav.c", 100.0, lane_y(2), 25.0), ("human.f", 60.0, lane_y(1), 15.0),
                 ("human.l", 110.0, lane_y(1), 15.0)])  # fmt: skip
    ch = _changes(["cav.c"], [2], [1.0], [100.0], [0.0], [25.0])
    s, chain_ids = ch.situation(gap, gap.x.copy(), np.array([0]), 0.0)
    unlimited = LaneChanges(None, PRM, brake_comfort=np.inf).planner(ch._observation(s, gap, chain_ids,
                                                                                     np.zeros(1, bool)), PRM)
    assert unlimited[0][0] == -PRM.a_x_d  # the paper's expert: emergency braking to place itself
    assert ch._proposal(s, gap, chain_ids, np.zeros(1, bool))[0][0] == pytest.approx(-BRAKE_COMFORT)
    # L1 far ahead (the expert wants to speed up), but a slow L0 12 m ahead in the own lane: the cap brakes
    own = fleet([("cav.c", 100.0, lane_y(2), 25.0), ("human.f", 90.0, lane_y(1), 25.0),
                 ("human.l", 200.0, lane_y(1), 25.0), ("human.o", 112.0, lane_y(2), 20.0)])  # fmt: skip
    s, chain_ids = ch.situation(own, own.x.copy(), np.array([0]), 0.0)
    assert s.own_x[0, 0] == 112.0
    expected = 0.3 * (112.0 - 100.0 - PRM.p_m - 1.0 * 25.0) + 0.8 * (20.0 - 25.0)
    assert ch._proposal(s, own, chain_ids, np.zeros(1, bool))[0][0] == pytest.approx(max(expected, -PRM.a_x_d))
    assert ch._proposal(s, own, chain_ids, np.ones(1, bool))[0][0] == pytest.approx(PRM.a_x_a)  # completed: L1's
    ch.l0_aware = False
    assert ch._proposal(s, own, chain_ids, np.zeros(1, bool))[0][0] == pytest.approx(PRM.a_x_a)


# -- an aborted lane change returns
class KinematicWorld:
    """A stand-in for :class:`safelane.traffic.world.TrafficWorld` without SUMO: the vehicles it drives keep their
    speeds (``pace``: this one is kept alongside ``ego`` in the target lane, ``ahead`` m in front, from the first
    period the ego's centre is more than ``when_y`` m off its lane's centre); the changers are where
    :class:`LaneChanges` places them."""

    def __init__(self, rows, ego, wish, pace=None, ahead=1.0, when_y=1.0):
        self.s = {vid: [x, y, v] for vid, x, y, v in rows}
        self.ego, self.wish, self.pace, self.ahead, self.when_y = ego, wish, pace, ahead, when_y
        self.y0 = self.s[ego][1]
        self.t, self.taken, self.released, self.pacing = 0.0, set(), [], False

    def time(self):
        return self.t

    def read(self):
        return fleet([(vid, *st) for vid, st in self.s.items()])

    def wishes(self, vids):
        return np.array([self.wish if vid == self.ego else 0 for vid in vids], np.int64)

    def take(self, vid):
        self.taken.add(vid)

    def release(self, vid):
        self.taken.discard(vid)
        self.released.append((self.t, vid, self.s[vid][1]))

    def place(self, vids, x, y, v):
        for vid, xi, yi, vi in zip(vids, x, y, v, strict=True):
            self.s[vid] = [float(xi), float(yi), float(vi)]

    def limit_braking(self, vids, decel):
        pass

    def step(self):
        for vid, st in self.s.items():
            if vid not in self.taken:
                st[0] += st[2] * PRM.dt
        self.t = round(self.t + PRM.dt, 9)
        ex, ey, ev = self.s[self.ego]
        self.pacing |= self.pace is not None and abs(ey - self.y0) > self.when_y
        if self.pacing:
            self.s[self.pace] = [ex + self.ahead, self.s[self.pace][1], ev]


def _run(world, changes, seconds):
    first_abort = None
    for _ in range(round(seconds / PRM.dt)):
        t = world.time()
        changes.period(world.read(), t)
        if first_abort is None and changes.counts["abort_steps"]:
            first_abort = t
        world.step()
        if world.released:
            break
    return first_abort


def test_an_aborted_lane_change_returns_to_its_own_lane_within_the_deadline():
    # cav.e in lane 1 starts a change to the left into a wide gap; once its centre is 1 m across, a human changes
    # into the target lane right beside it and stays there: the shield aborts. The expert still wants the target
    # lane and, proposed again after the abort, kept the vehicle at the conflict zone's edge (0.85 m off its lane's
    # centre) for as long as the human stayed; now it returns and SUMO gets it back within the deadline.
    rows = [("cav.e", 500.0, lane_y(1), 25.0), ("human.f", 440.0, lane_y(0), 25.0),
            ("human.l", 560.0, lane_y(0), 25.0), ("human.p", -5000.0, lane_y(0), 25.0)]  # fmt: skip
    world = KinematicWorld(rows, "cav.e", wish=1, pace="human.p")
    changes = LaneChanges(world, PRM, return_deadline_s=8.0)
    first_abort = _run(world, changes, 40.0)
    assert first_abort is not None and world.pacing  # the shield did abort
    assert world.released, "the aborted change never returned to its own lane"
    t_rel, vid, y = world.released[0]
    assert vid == "cav.e" and y == lane_y(1)  # back on its own lane's centre
    assert t_rel - first_abort <= changes.return_deadline_s
    assert changes.counts["aborted"] == 1 and changes.counts["completed"] == 0
    assert changes.counts["return_late"] == 0 and 0.0 < changes.counts["return_max_s"] <= 8.0


def test_a_change_that_never_gets_its_gap_is_given_up_and_returns():
    # the human beside it from the start: the shield lets it up to the conflict zone's edge and no further (it
    # hesitates there, never aborting); give_up_s after the start it returns, within the deadline
    rows = [("cav.e", 500.0, lane_y(1), 25.0), ("human.p", 501.0, lane_y(0), 25.0)]
    world = KinematicWorld(rows, "cav.e", wish=1, pace="human.p", when_y=-1.0)
    changes = LaneChanges(world, PRM, give_up_s=5.0, return_deadline_s=8.0)
    ys = []
    real_place = world.place
    world.place = lambda vids, x, y, v: (ys.append(float(y[0]) - lane_y(1)), real_place(vids, x, y, v))
    _run(world, changes, 30.0)
    assert max(ys) == pytest.approx(PRM.y_safe, abs=0.01)  # it got to the edge (no further) ...
    assert world.released and world.released[0][1:] == ("cav.e", lane_y(1))  # ... and came back
    assert 5.0 < world.released[0][0] <= 5.0 + 8.0
    assert changes.counts["gave_up"] == 1 and changes.counts["aborted"] == 0 and changes.counts["completed"] == 0
    assert changes.counts["hesitate"] > 0 and changes.counts["abort_steps"] == 0
    assert 0.0 < changes.counts["return_max_s"] <= 8.0 and changes.counts["return_late"] == 0


def test_a_collision_is_judged_with_the_lane_change_made_in_its_own_step():
    """The seed-1 sweep's p = 0.75 case (t = 954.3 s): ``human.1151`` changed from lane 2 into lane 1 in one SUMO
    step, its rear 1.7 m behind the front of ``cav.1149``, which straddled lanes 0 and 1; SUMO listed the collision
    after that step with ``cav.1149`` as the collider. Judged with the entries read before the step, the cut-in was
    unseen and ``cav.1149`` blamed (rule "rear"); the referee judges it at the next read, with the entry."""
    referee = measures.Referee(PRM.vehicle_length, PRM.vehicle_width)
    before = fleet([("cav.1149", 2054.6, -3.49, 22.3), ("human.1151", 2057.3, lane_y(2), 28.2)])
    assert referee.observe(954.2, before) == []
    crash = {"t": 954.3, "collider": "cav.1149", "victim": "human.1151", "type": "collision"}
    referee.collided([crash])
    assert referee.judged == []  # not yet: the step's lane entries are read with the next period
    after = fleet([("cav.1149", 2057.05, -3.56, 22.3), ("human.1151", 2060.16, lane_y(1), 28.4)])
    new = referee.observe(954.3, after)
    assert [(e["vid"], e["lane"], e["follower"]) for e in new] == [("human.1151", 1, "cav.1149")]
    assert [(j["responsible"], j["rule"]) for j in referee.judged] == [("human.1151", "cut-in")]
    # judged at once, with the entries before the step (the old order): the rear vehicle
    assert measures.blame([crash], [])[0]["responsible"] == "cav.1149"
