"""Traffic in the lanes beside (``SimConfig.neighbours``, safelane.sim.neighbours) and the lane-cost experiment.

The platoons against their definition written out here (bounds, one speed per lane, spacing = headway · speed +
length), their independence of the batch they are drawn in, the shield folding them (a lane-2 neighbour that can get
ahead cuts the connected chain: world-model rule 5, by hand), and the simulator's outcomes: they keep their lanes, so
in the guarantee's mode no collision and no ``p_m`` violation appears, and the ego only completes less often."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.errors import InputError
from safelane.experiments.lane_cost import cost_table, text
from safelane.shield.world import roles
from safelane.sim import ScenarioConfig, SimConfig, paper_scenarios, simulate_batch
from safelane.sim.engine import simulate
from safelane.sim.neighbours import BACK_M, FRONT_M, MIN_SPEED_MPS, Neighbours, slots
from safelane.sim.step import ClosedLoop

PRM = Params()
CFG = SimConfig(neighbours=True, neighbour_headway_min_s=1.2, neighbour_headway_max_s=2.5,
                neighbour_speed_spread_mps=4.0)  # fmt: skip


def _batch(samples=64, first_id=0, planner="CV_all", n=2, decel=5.0):
    return paper_scenarios(planner, n, decel, samples, np.random.default_rng(first_id), ScenarioConfig(),
                           first_id=first_id)  # fmt: skip


def test_the_platoons_are_what_the_definition_says():
    b = _batch(200)
    nb = Neighbours(b, 7, CFG, PRM)
    k = slots(CFG, PRM)
    assert nb.x0.shape == nb.v.shape == (200, 2 * k)
    assert nb.y.tolist() == [-PRM.lane_width] * k + [2 * PRM.lane_width] * k
    for lane in range(2):
        x, v = nb.x0[:, lane * k : (lane + 1) * k], nb.v[:, lane * k : (lane + 1) * k]
        for i in range(200):
            present = np.isfinite(x[i])
            xi = x[i][present]
            assert present[: len(xi)].all() and len(xi) >= 2  # vehicles first, padding after
            assert xi[0] >= b.ego_x[i] - BACK_M and xi[-1] <= b.ego_x[i] + FRONT_M
            speed = v[i, 0]
            assert np.all(v[i] == speed)  # one speed per lane
            assert max(b.ego_vx[i] - 4.0, MIN_SPEED_MPS) <= speed <= b.ego_vx[i] + 4.0
            headway = (np.diff(xi) - PRM.vehicle_length) / speed
            assert headway.min() >= 1.2 - 1e-9 and headway.max() <= 2.5 + 1e-9
            # the platoon reaches the front: one more gap at the longest headway would pass it
            assert xi[-1] + 2.5 * speed + PRM.vehicle_length > b.ego_x[i] + FRONT_M
    others = nb.at(2.0)
    assert np.array_equal(others.x, nb.x0 + 2.0 * nb.v) and not others.connected.any() and (others.vy == 0).all()


def test_a_scenarios_neighbours_do_not_depend_on_its_batch():
    b = _batch(64)
    whole = Neighbours(b, 3, CFG, PRM)
    rows = np.array([5, 17, 40])
    part = Neighbours(b.take(rows), 3, CFG, PRM)
    assert np.array_equal(whole.x0[rows], part.x0) and np.array_equal(whole.v[rows], part.v)
    assert not np.array_equal(Neighbours(b, 4, CFG, PRM).x0, whole.x0)  # the seed matters


def test_the_shield_counts_a_neighbour_ahead_beyond_the_target_lane():
    b = _batch(64)
    loop = ClosedLoop(b, 0, PRM, CFG, None)
    s = loop.initial_state()
    situation = loop.situation(0.0, s.ego, s.x, s.v, None, b.v[:, 0], None)
    assert situation.others is not None
    folded = roles(situation, PRM)
    o, n = situation.others, situation.n_connected
    assert (situation.ego_y == 0.0).all() and (situation.ego_vy == 0.0).all()
    # by hand (world-model rule 5): a lane-2 neighbour counts at its own position once it is p_m plus RSS's distance
    # ahead of the ego (the ego's stopping distance, a_x_a for dt then a_x_d, less the neighbour's at a_o_d = a_x_d),
    # else at ego_x + p_m where it can get p_m ahead within the dilemma — here one period (the ego in its lane: an
    # evasion adopted now keeps no part of it in the target lane), it at a_x_a, the ego braking at a_x_d
    dt, up, dn, ev = PRM.dt, PRM.a_x_a, PRM.a_x_d, situation.ego_vx[:, None]
    assert PRM.others_decel == dn and (ev > dn * dt).all()
    stop = ev * dt + 0.5 * up * dt * dt + (ev + up * dt) ** 2 / (2 * dn)
    gap = o.x - situation.ego_x[:, None] - PRM.p_m
    lane2 = o.y == 2 * PRM.lane_width
    ready = lane2 & (gap >= np.maximum(stop - o.vx**2 / (2 * dn), 0.0))
    cut = lane2 & ~ready & (gap + (o.vx - ev) * dt + 0.5 * (up + dn) * dt * dt >= 0.0)
    first = np.minimum(np.where(ready, o.x, np.inf).min(1), np.where(cut.any(1), situation.ego_x + PRM.p_m, np.inf))
    assert ready.any() and cut.any()
    # the connected chain keeps the leaders before the first of them, and ends there
    slot = np.arange(situation.chain_x.shape[1])[None, :]
    expected = ((situation.chain_x < first[:, None]) & (slot < n[:, None])).sum(1)
    assert np.array_equal(folded.n_connected, expected)
    assert (expected == 0).any() and (expected < n).any() and (expected == n).any()
    assert (o.y == -PRM.lane_width).any() and folded.own_x is not None  # lane -1 ahead: a virtual L0 (rule 4)


def test_with_neighbours_the_guarantee_holds_and_the_ego_completes_less_often():
    b = _batch(160, planner="CV_all", n=3, decel=4.0)
    paper = simulate_batch(b, seed=2, params=PRM, config=SimConfig())
    wide = simulate_batch(b, seed=2, params=PRM, config=CFG)
    assert wide.engine == "period by period"
    for result in (paper, wide):
        t = result.table
        assert not t["collision"].any() and not t["safety_violation"].any()
    assert wide.table["success"].mean() < paper.table["success"].mean()


def test_headways_must_be_ordered():
    with pytest.raises(ValueError, match=r"neighbour_headway_max_s=0\.5 must be >= neighbour_headway_min_s=1\.0"):
        SimConfig(neighbour_headway_max_s=0.5)
    with pytest.raises((ValueError, InputError), match="neighbour_headway_min_s"):
        SimConfig(neighbour_headway_min_s=0.0)


def test_the_cost_table_runs_both_worlds_on_the_same_cells():
    table = cost_table("safe", samples=60, seed=1, n_values=(3,), decels=(4.0,), planners=("CV_all",))
    row = table.iloc[0]
    alone = simulate("CV_all", 3, 4.0, 60, 1, preset="safe").summary().iloc[0]
    assert row["paper_world_success"] == alone["success_rate"]
    assert row["cost"] == pytest.approx(row["paper_world_success"] - row["neighbours_success"])
    assert row["neighbours_collision"] == 0.0 and row["neighbours_pm_violation"] == 0.0
    assert "| 3 | 4 | CV_all |" in text(table)
