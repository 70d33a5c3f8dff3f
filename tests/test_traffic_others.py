"""The traffic co-simulation's feed of the shield's world model (safelane.traffic, docs/traffic.md): the changers'
``Situation.others`` from a hand-built fleet (the lane beyond the target and the other side, in the shield's frame,
never F, the chain or L0, the window), equipped changers' lane-change announcements, SUMO's continuous lane changes
(``lc_duration_s``) and a short SUMO cell with the feed on."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.shield.world import NO_LANE, PAD_M, roles
from safelane.traffic.demand import Demand, lane_of, lane_y
from safelane.traffic.equipped import OTHERS_SLOTS, OTHERS_WINDOW_M, LaneChanges

PRM = Params()
W = PRM.lane_width


def fleet(rows):
    """A fleet from ``(id, x, y, v, vy)`` rows (lane from ``y``, equipped by the id; ``vy`` road frame, + left)."""
    ids, x, y, v, vy = zip(*rows, strict=True)
    y = np.array(y, float)
    return SimpleNamespace(ids=tuple(ids), x=np.array(x, float), y=y, v=np.array(v, float), a=np.zeros(len(ids)),
                           lane=lane_of(y), equipped=np.array([i.startswith("cav.") for i in ids]),
                           vy=np.array(vy, float))  # fmt: skip


def changes(f, rows):
    """A :class:`LaneChanges` with the feed on and the changers ``rows``: ``(id, g0, sign, ey, evy, t0, ret)``."""
    ch = LaneChanges(None, PRM, others=True)
    ids, g0, sign, ey, evy, t0, ret = zip(*rows, strict=True)
    index = [f.ids.index(i) for i in ids]
    ch.ids, ch.g0, ch.sign = list(ids), np.array(g0, np.int64), np.array(sign, float)
    ch.ex, ch.evx = f.x[index].copy(), f.v[index].copy()
    ch.ey, ch.evy = np.array(ey, float), np.array(evy, float)
    ch.t0, ch.t_done, ch.t_ret, ch.t_abort = np.array(t0, float), *(np.full(len(ids), np.nan) for _ in range(3))
    ch.aborted, ch.late = np.zeros(len(ids), bool), np.zeros(len(ids), bool)
    ch.ret = np.array(ret, bool)
    return ch, np.array(index)


def present(o, row):
    return np.flatnonzero(np.isfinite(o.x[row]))


def test_the_others_are_the_lanes_beyond_and_beside_in_the_shield_frame_once_and_within_the_window():
    f = fleet([
        # row 0: cav.r in lane 0 changes right (target lane 1; beyond it lane 2; no lane on its other side)
        ("cav.r", 100.0, lane_y(0), 25.0, 0.0),
        ("human.f", 90.0, lane_y(1), 24.0, 0.0),  # F
        ("human.l1", 120.0, lane_y(1), 24.0, 0.0),  # L1
        ("human.s", 140.0, lane_y(2) + 1.9, 24.0, 0.0),  # straddles lanes 2 and 1: L2, not an other
        ("human.l0", 115.0, lane_y(0), 26.0, 0.0),  # L0
        ("human.b", 110.0, lane_y(2) + 0.3, 23.0, 2.0),  # lane 2, moving left (toward lane 1) at 2 m/s
        ("human.far", 100.0 + OTHERS_WINDOW_M + 1.0, lane_y(2), 23.0, 0.0),  # beyond the window
        ("human.back", 100.0 - OTHERS_WINDOW_M - 1.0, lane_y(2), 23.0, 0.0),  # behind the window
        # row 1: cav.l in lane 2 changes left (target lane 1; beyond it lane 0; the other side: the acceleration lane)
        ("cav.l", 1100.0, lane_y(2), 25.0, 0.0),
        ("human.m", 1110.0, lane_y(3), 20.0, 1.0),  # acceleration lane, moving left (toward lane 2) at 1 m/s
        ("human.z", 1050.0, lane_y(0), 30.0, 0.0),  # lane 0, beyond the target
        ("human.o", 1105.0, lane_y(2), 20.0, 0.0),  # L0 of row 1
    ])  # fmt: skip
    ch, rows = changes(f, [("cav.r", 0, -1.0, 0.0, 0.0, 0.0, False), ("cav.l", 2, 1.0, 0.0, 0.0, 0.0, False)])
    s, chain_ids = ch.situation(f, f.x.copy(), rows, 5.0)
    o = s.others
    assert o.x.shape == (2, OTHERS_SLOTS)
    # row 0: human.b only, once; shield frame: y = 2 w − 0.3 (toward the target is toward smaller y), vy = −2
    assert present(o, 0).tolist() == [0]
    assert (o.x[0, 0], o.vx[0, 0]) == (110.0, 23.0)
    assert o.y[0, 0] == pytest.approx(2 * W - 0.3) and o.vy[0, 0] == pytest.approx(-2.0)
    assert not o.connected[0, 0] and o.announce_lane[0, 0] == NO_LANE  # a human: not connected, no announcement
    assert np.isinf(o.x[0, 1:]).all()  # padding (human.far, human.back outside the window)
    # F, the chain and L0 are not repeated
    assert (s.f_x[0], s.own_x[0, 0]) == (90.0, 115.0)
    assert [f.ids[i] for i in chain_ids[0, :2]] == ["human.l1", "human.s"]
    assert not set(o.x[0][np.isfinite(o.x[0])]) & {90.0, 115.0, 120.0, 140.0}
    # row 1 (a left change): nearest first — human.m in lane −1 moving toward the own lane (+1 m/s), human.z in
    # lane 2 (beyond the target)
    assert present(o, 1).tolist() == [0, 1]
    assert o.x[1, :2].tolist() == [1110.0, 1050.0]
    assert o.y[1, :2] == pytest.approx([-W, 2 * W]) and o.vy[1, :2] == pytest.approx([1.0, 0.0])
    assert s.own_x[1, 0] == 1105.0 and 1105.0 not in o.x[1]
    # the shield folds them: human.b reaches the target lane by RSS's lateral rule (2 m/s toward it) and becomes
    # L1 ahead of human.l1 (non-connected: N = 0, the slots beyond are padding); human.m (1 m/s toward cav.l's lane)
    # and human.z have no role
    folded = roles(s, PRM)
    assert folded.chain_x[0, :2].tolist() == [110.0, 110.0 + PAD_M] and folded.n_connected[0] == 0
    assert folded.own_x[1, 0] == 1105.0 and folded.f_x[1] == s.f_x[1]
    assert folded.chain_x[1].tolist() == s.chain_x[1].tolist()
    # the same fleet with human.b not moving: ahead of cav.r in lane 2 it still counts (world-model rule 5, at the
    # cut-in bound); moved behind cav.r (nearer than F) it reaches nothing and changes nothing
    def moved(x_b):
        return fleet([(r[0], x_b if r[0] == "human.b" else r[1], r[2], r[3], 0.0 if r[0] == "human.b" else r[4])
                      for r in zip(f.ids, f.x, f.y, f.v, f.vy, strict=True)])  # fmt: skip

    for x_b, counts in ((110.0, True), (95.0, False)):
        still = moved(x_b)
        s2, _ = ch.situation(still, still.x.copy(), rows, 5.0)
        folded2 = roles(s2, PRM)
        assert s2.others.vy[0, 0] == 0.0 and s2.others.x[0, 0] == x_b
        # counted: 110 m is short of RSS's entry distance ahead of the ego, so at the cut-in bound ego_x + p_m
        assert (folded2.chain_x[0, 0] == s2.ego_x[0] + PRM.p_m and folded2.n_connected[0] == 0) == counts
        assert (folded2.chain_x[0].tolist() == s2.chain_x[0].tolist()) != counts
        assert folded2.f_x[0] == s2.f_x[0] == 90.0
    # the feed off: no record (the paper's world, as before)
    ch.others = False
    assert ch.situation(f, f.x.copy(), rows, 5.0)[0].others is None


def test_an_equipped_changer_announces_the_lane_it_will_enter():
    f = fleet([
        ("cav.a", 100.0, lane_y(0), 25.0, 0.0),  # row 0: lane 0 -> lane 1 (right)
        ("cav.b", 110.0, lane_y(2) + 0.4, 24.0, 0.0),  # row 1: lane 2 -> lane 1 (left), 0.4 m across already
        ("cav.c", 80.0, lane_y(2) + 0.6, 22.0, 0.0),  # row 2: lane 2 -> lane 1 aborted, returning to lane 2
        ("cav.q", 150.0, lane_y(2), 26.0, 0.0),  # equipped, not changing: connected, no announcement
        ("human.h", 60.0, lane_y(2), 26.0, 0.0),  # human: not connected
    ])  # fmt: skip
    ch, rows = changes(f, [("cav.a", 0, -1.0, 0.0, 0.0, 3.0, False), ("cav.b", 2, 1.0, 0.4, 0.7, 4.5, False),
                           ("cav.c", 2, 1.0, 0.6, -0.5, 1.0, True)])  # fmt: skip
    s, _ = ch.situation(f, f.x.copy(), rows, 6.0)
    o = s.others
    by_x = {float(x): k for k, x in enumerate(o.x[0]) if np.isfinite(x)}
    assert sorted(by_x) == [60.0, 80.0, 110.0, 150.0]
    b, c, q, h = (by_x[x] for x in (110.0, 80.0, 150.0, 60.0))
    # cav.b: in row 0's frame it enters lane 1 (row 0's target) from lane 2, started at 4.5 s; its exact lateral
    # speed (0.7 m/s to the left) is toward row 0's target: −0.7
    assert (o.connected[0, b], o.announce_lane[0, b], o.announce_t[0, b]) == (True, 1, 4.5)
    assert o.y[0, b] == pytest.approx(2 * W - 0.4) and o.vy[0, b] == pytest.approx(-0.7)
    # cav.c returns to its own lane 2: announced lane 2 (beyond row 0's target), lateral speed away from it
    assert (o.connected[0, c], o.announce_lane[0, c], o.announce_t[0, c]) == (True, 2, 1.0)
    assert o.vy[0, c] == pytest.approx(0.5)
    assert (o.connected[0, q], o.announce_lane[0, q]) == (True, NO_LANE) and np.isinf(o.announce_t[0, q])
    assert (o.connected[0, h], o.announce_lane[0, h]) == (False, NO_LANE)
    # row 1 (cav.b, left): cav.a in lane 0 (beyond its target) announces lane 1, its target too
    k = int(np.flatnonzero(o.x[1] == 100.0)[0])
    assert (o.connected[1, k], o.announce_lane[1, k], o.announce_t[1, k]) == (True, 1, 3.0)
    assert o.y[1, k] == pytest.approx(2 * W)
    # the shield takes the announcement: cav.b counts in row 0's target lane ahead of cav.a -> its L1 (non-connected,
    # N = 0), though its body is not yet across the line; cav.c (announcing lane 2) plays no role
    folded = roles(s, PRM)
    assert folded.chain_x[0, 0] == 110.0 and folded.n_connected[0] == 0
    assert folded.f_x[0] == s.f_x[0]
    # more than the announcement horizon before its start, the announcement does not count yet
    ch.t0[1] = 6.0 + 10.5
    early = roles(ch.situation(f, f.x.copy(), rows, 6.0)[0], PRM)
    assert early.chain_x[0, 0] != 110.0


def _libsumo():
    from safelane.integrations.sumo_world import libsumo_available

    if not libsumo_available():
        pytest.skip("libsumo is not installed: pip install 'safelane[sumo]'")


def _lateral_steps(lc_duration_s: float, seconds: float = 40.0):
    """Per mainline vehicle and step past the ramp's junction (x > 960 m): Δy between periods and SUMO's lateral
    speed before it. Run in a fresh process (:func:`_fresh`): libsumo keeps ``--lanechange.duration`` past
    ``close()`` (measured: a run with 0 after one with 3 s in the same process still changed lanes continuously, and
    one with 3 s after it had lateral jumps)."""
    from safelane.traffic.world import TrafficWorld

    demand = Demand(p=0.0, main_vph=3000, ramp_vph=600, seconds=seconds, warmup_s=10, seed=1,
                    lc_duration_s=lc_duration_s)  # fmt: skip
    dy, vy_before, prev = [], [], {}
    with TrafficWorld(demand, PRM, ssm=False) as world:
        for _ in range(round(seconds / PRM.dt)):
            f = world.read()
            for vid, x, y, vy, lane in zip(f.ids, f.x.tolist(), f.y.tolist(), f.vy.tolist(), f.lane.tolist(),
                                           strict=True):  # fmt: skip
                if lane < 0 or (x < 960.0 and lane == 3):
                    continue
                if vid in prev:
                    dy.append(y - prev[vid][0])
                    vy_before.append(prev[vid][1])
                prev[vid] = (y, vy)
            world.step()
    return np.array(dy), np.array(vy_before)


def _fresh(fn, *args):
    """``fn(*args)`` in a fresh interpreter (libsumo is a singleton that keeps state past ``close()``)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


def test_continuous_lane_changes_move_sumos_vehicles_laterally_step_by_step():
    _libsumo()
    jump, _ = _fresh(_lateral_steps, 0.0)
    assert np.abs(jump).max() > 0.9 * W  # SUMO's default: a lane change is one jump of a lane width
    dy, vy = _fresh(_lateral_steps, 3.0)
    moving = np.abs(vy) > 0.05
    assert moving.sum() > 50  # lane changes happened
    assert np.abs(dy).max() <= W / 3.0 * PRM.dt + 1e-6  # no jumps: at most a lane width over 3 s, per 0.1 s step
    assert np.abs(vy).max() == pytest.approx(W / 3.0)  # SUMO's lateral speed: a lane width over the duration
    # the reported lateral speed is the lateral motion: its sign (+: left, +y) is that of the next step's Δy
    assert (np.sign(dy[moving]) == np.sign(vy[moving])).mean() > 0.95


def test_a_short_cell_with_the_feed_on_has_no_collision_an_equipped_vehicle_is_responsible_for():
    _libsumo()
    from safelane.traffic import run

    job = run.cells([1.0], [3900.0], seconds=60, warmup_s=10, seed=1, ramp_share=900 / 3900, others=True,
                    lc_duration_s=3.0)  # fmt: skip
    out = run._cell_job(job[0])  # a fresh process, as every cell of a sweep
    row, seen = out["row"], out["lane_changes"]
    assert row["others"] is True and row["lc_duration_s"] == 3.0
    assert row["lc_started"] > 0 and row["lc_completed"] > 0 and row["shield_calls"] > 0
    # vehicles beyond the target lane and on the other side, and equipped changers' announcements, reached the shield
    assert seen["others_slots"] > 100 and 0 < seen["others_announced"] <= seen["others_connected"]
    assert row["collisions_equipped_responsible"] == 0
