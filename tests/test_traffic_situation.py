"""The changers' batch situation of the traffic co-simulation (``LaneChanges.situation``: the neighbour search of
:mod:`safelane.traffic.lanes`, compiled where numba is and as Python where not) against a plain reference written
here changer by changer and lane by lane from the rules of docs/traffic.md: random fleets with ties in position,
vehicles across lane boundaries, the ramp, changers that completed, that return and that are still changing."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.traffic import demand as dem
from safelane.traffic import lanes
from safelane.traffic.equipped import CHAIN_SLOTS, FAR_M, PROMISE_DECEL, LaneChanges

PRM = Params()
HALF = 0.5 * (PRM.lane_width + PRM.vehicle_width) - 1e-6


def random_scene(seed: int, n: int):
    """A fleet of ``n`` vehicles on a 400 m stretch around the ramp (positions on a 2 m grid: ties), some across
    lane boundaries, some on the ramp, and a third of the equipped ones changing lanes."""
    rng = np.random.default_rng(seed)
    lane = rng.integers(0, dem.N_LANES, n)
    y = dem.lane_y(lane) + rng.choice([0.0, 0.0, 0.0, 1.0, -1.0, 1.9, -1.9], n)
    road_lane = dem.lane_of(y)
    road_lane = np.where((road_lane < 0) | (road_lane >= dem.N_LANES), lane, road_lane)
    road_lane[rng.random(n) < 0.05] = -1  # on the ramp
    x = 900.0 + 2.0 * rng.integers(0, 200, n)
    v = np.round(rng.uniform(5.0, 33.0, n), 1)
    equipped = rng.random(n) < 0.6
    fleet = SimpleNamespace(ids=tuple(f"v{i}" for i in range(n)), x=x, y=y, v=v, a=np.zeros(n), lane=road_lane,
                            equipped=equipped)  # fmt: skip
    cand = np.flatnonzero(equipped & (road_lane >= 0))
    rows = rng.choice(cand, size=max(1, len(cand) // 3), replace=False)
    b = len(rows)
    ch = LaneChanges(None, PRM)
    g0 = road_lane[rows]
    sign = np.where(g0 == 0, -1.0, np.where(g0 == dem.ACCEL_LANE, 1.0, rng.choice([-1.0, 1.0], b)))
    ch.ids, ch.g0, ch.sign = [fleet.ids[i] for i in rows], g0, sign
    ch.ex, ch.evx = x[rows].copy(), v[rows].copy()
    ch.ey, ch.evy = rng.uniform(0.0, 3.0, b), np.zeros(b)
    ch.t0, ch.t_ret, ch.t_abort = np.zeros(b), np.full(b, np.nan), np.full(b, np.nan)
    ch.t_done = np.where(rng.random(b) < 0.3, 1.0, np.nan)
    ch.ret = np.isnan(ch.t_done) & (rng.random(b) < 0.3)
    ch.aborted, ch.late = ch.ret.copy(), np.zeros(b, bool)
    return fleet, ch, rows


def reference(fleet, ch, rows):
    """The rules, changer by changer (sorted lanes built with Python's ``sorted``)."""
    n = len(fleet.ids)
    members = {g: sorted((i for i in range(n) if fleet.lane[i] >= 0 and abs(fleet.y[i] - dem.lane_y(g)) < HALF),
                         key=lambda i: (fleet.x[i], i)) for g in range(dem.N_LANES)}  # fmt: skip
    kept = {}  # changer fleet index -> the lane it stays in (None: not yet)
    for r, i in enumerate(rows):
        target = int(ch.g0[r] - ch.sign[r])
        settled = ch.ret[r] or not np.isnan(ch.t_done[r])
        kept[i] = (int(ch.g0[r]) if ch.ret[r] else target) if settled else None
    out = []
    for r, i in enumerate(rows):
        ex, target, g0 = fleet.x[i], int(ch.g0[r] - ch.sign[r]), int(ch.g0[r])
        lane = members[target]
        behind = [j for j in lane if fleet.x[j] < ex]
        ahead = [j for j in lane if fleet.x[j] > ex]
        if behind:
            f_x, f_con = fleet.x[behind[-1]], bool(fleet.equipped[behind[-1]])
            f_v = -np.inf
            for j in reversed(behind):  # back to (and with) the nearest that stays
                f_v = max(f_v, fleet.v[j])
                if kept.get(j, target) == target:
                    break
        else:
            f_x, f_v, f_con = ex - FAR_M, 0.0, False
        chain = ahead[:CHAIN_SLOTS]
        lx = [fleet.x[j] for j in chain] + [ex + FAR_M * (1 + k) for k in range(len(chain), CHAIN_SLOTS)]
        lv = [fleet.v[j] for j in chain] + [ch.evx[r]] * (CHAIN_SLOTS - len(chain))
        n_conn = 0
        while n_conn < min(len(chain), CHAIN_SLOTS - 1) and fleet.equipped[chain[n_conn]]:
            n_conn += 1
        own = [j for j in members[g0] if fleet.x[j] > ex]
        o_x, o_v = (fleet.x[own[0]], fleet.v[own[0]]) if own else (np.inf, 0.0)
        end = dem.ACCEL_X[1] + 0.5 * PRM.vehicle_length
        if g0 == dem.ACCEL_LANE and not o_x < end:
            o_x, o_v = end, 0.0
        out.append((f_x, f_v, f_con, lx, lv, n_conn, o_x, o_v, chain))
    return out


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
@pytest.mark.parametrize("seed", range(12))
def test_the_batch_situation_follows_the_rules_changer_by_changer(monkeypatch, seed, compiled):
    if compiled and lanes._kernel() is None:
        pytest.skip("numba missing or SAFELANE_NO_NUMBA=1")
    if not compiled:
        monkeypatch.setattr(lanes, "_kernel", lambda: None)
    fleet, ch, rows = random_scene(seed, n=[3, 20, 80][seed % 3])
    s, chain_ids = ch.situation(fleet, fleet.x.copy(), rows, 7.0)
    s.validate(PRM)
    for r, (f_x, f_v, f_con, lx, lv, n_conn, o_x, o_v, chain) in enumerate(reference(fleet, ch, rows)):
        assert (s.f_x[r], s.f_v[r], bool(s.f_connected[r])) == (f_x, f_v, f_con), r
        assert s.chain_x[r].tolist() == lx and s.chain_v[r].tolist() == lv, r
        assert [int(j) for j in chain_ids[r] if j >= 0] == chain and int(s.n_connected[r]) == n_conn, r
        assert (s.own_x[r, 0], s.own_v[r, 0]) == (o_x, o_v), r
    assert (s.chain_promise == PROMISE_DECEL).all() and not s.chain_human.any() and not s.f_collaborative.any()
    assert (s.ego_x == ch.ex).all() and (s.ego_y == ch.ey).all() and s.others is None


def test_an_empty_lane_and_a_changer_alone():
    # the changer alone on the road: no F, no chain, no L0 (padded); in the acceleration lane, its end is L0
    for g0, sign in ((1, 1.0), (dem.ACCEL_LANE, 1.0)):
        fleet = SimpleNamespace(ids=("cav.0",), x=np.array([1000.0]), y=dem.lane_y(np.array([g0])), a=np.zeros(1),
                                v=np.array([20.0]), lane=np.array([g0]), equipped=np.array([True]))  # fmt: skip
        ch = LaneChanges(None, PRM)
        ch.ids, ch.g0, ch.sign = ["cav.0"], np.array([g0]), np.array([sign])
        ch.ex, ch.evx, ch.ey, ch.evy = np.array([1000.0]), np.array([20.0]), np.zeros(1), np.zeros(1)
        ch.t_done, ch.ret = np.full(1, np.nan), np.zeros(1, bool)
        s, chain_ids = ch.situation(fleet, fleet.x.copy(), np.array([0]), 0.0)
        assert s.f_x[0] == 1000.0 - FAR_M and s.f_v[0] == 0.0 and not s.f_connected[0]
        assert s.chain_x[0].tolist() == [1000.0 + FAR_M * (1 + k) for k in range(CHAIN_SLOTS)]
        assert (chain_ids == -1).all() and s.n_connected[0] == 0
        end = dem.ACCEL_X[1] + 0.5 * PRM.vehicle_length
        assert (s.own_x[0, 0], s.own_v[0, 0]) == ((end, 0.0) if g0 == dem.ACCEL_LANE else (np.inf, 0.0))
