"""The multi-lane falsifier (safelane.experiments.falsify_lanes): its world, its referee, its report.

The referee must be able to fail: without the shield the reckless planner crashes and the blame rule names the ego;
an entrant that ignores the entering rule is counted outside the assumptions; the entry distance is checked against
RSS's distance written out here; the same seed gives the same outcomes."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.experiments import falsify_lanes as fl
from safelane.experiments import falsify_lanes_world as flw
from safelane.experiments.falsify_lanes_run import run
from safelane.shield import ShieldConfig

PRM = Params()


def spec(n=64, seed=3):
    return fl.draw(np.random.default_rng(seed), n, PRM)


def test_without_the_shield_the_referee_sees_ego_responsible_collisions():
    s = spec(128)
    s["ax_hi"][:] = s["ax_lo"][:] = PRM.a_x_a  # full throttle into the target lane
    s["start_s"][:] = 0.0
    off = fl.simulate(s, fl.LaneWorld(config=ShieldConfig(enabled=False), horizon_s=6.0))
    assert off.collided.sum() > 10
    assert (off.ego_collision & off.collided).sum() >= 0.8 * off.collided.sum()
    assert not (off.ego_collision & ~off.collided).any()


def test_an_entrant_that_ignores_the_entering_rule_is_outside_the_assumptions():
    s = spec(64)
    s["ego_y"][:] = 0.0
    s["start_s"][:] = 10.0  # the ego stays in its lane, at its speed
    s["ax_hi"][:] = s["ax_lo"][:] = 0.0
    s["far_present"][:] = False
    s["side_present"][:] = True
    s["side_x"][:] = 2.0  # beside the ego, at its speed: it may never enter the ego's lane
    s["side_dv"][:] = 0.0
    s["side_want_t"][:] = 0.0
    s["side_connected"][:] = False
    world = fl.LaneWorld(config=ShieldConfig(enabled=False), horizon_s=3.0)  # the proposal (hold) passes through
    honest = fl.simulate(s, world)
    assert honest.entries.sum() == 0  # beside the ego, nobody may enter
    s["side_margin"][:] = -1e3  # enters whatever the distance
    rogue = fl.simulate(s, world)
    assert (rogue.entries > 0).all() and not rogue.inside.any()
    assert (rogue.started == honest.started).all()


def test_the_entry_distance_is_rss_plus_p_m_by_hand():
    v_rear, v_front = 30.0, 25.0
    rho, a, b, b_front = PRM.dt, PRM.a_x_a, PRM.a_x_d, PRM.others_decel
    v_r = v_rear + a * rho
    by_hand = v_rear * rho + 0.5 * a * rho**2 + v_r**2 / (2 * b) - v_front**2 / (2 * b_front) + PRM.p_m
    assert flw.safe_gap(v_rear, v_front, PRM) == pytest.approx(by_hand, abs=1e-9)
    x = np.array([[-1e3, 1e3, np.inf, 0.0, np.inf]])  # the far entrant at 0, the ego (in lane 1) ahead
    v = np.array([[0.0, 0.0, 0.0, v_rear, 0.0]])
    y = np.array([[7.0, 3.5, 0.0, 7.0, -3.5]])
    vy = np.zeros_like(x)
    ego_x, ego_v = np.array([by_hand]), np.array([v_front])

    def ok(dx, ego_y, ego_vy=0.0):
        ego = (ego_x + dx, np.array([ego_y]), ego_v, np.array([ego_vy]))
        return bool(flw.may_enter(flw.FAR, x, v, y, vy, ego, PRM, 0.0)[0])

    assert ok(1e-6, 3.5) and not ok(-1e-6, 3.5)
    assert ok(-1e-6, 0.0)  # the ego in its own lane, not moving: it does not count
    # moving toward lane 1 its RSS reach counts: body edge 0.2 m short of the line, reach 0.2 m near 0.40 m/s by hand
    edge_y = 0.5 * PRM.lane_width - 0.5 * PRM.vehicle_width - 0.2
    reach = lambda u: 0.5 * 1.5 * 0.01 + u * 0.1 + (u + 0.15) ** 2 / 3.0 + 0.05  # noqa: E731
    assert reach(0.39) < 0.2 < reach(0.42)
    assert ok(-1e-6, edge_y, 0.39) and not ok(-1e-6, edge_y, 0.42)


def test_same_seed_same_outcomes_and_the_report_adds_up():
    a = run(96, seed=5, batch_size=48, world=fl.LaneWorld(horizon_s=4.0))
    b = run(96, seed=5, batch_size=48, world=fl.LaneWorld(horizon_s=4.0))
    assert a.counts == b.counts and a.generated == 96
    total = sum(c["scenarios"] for c in a.counts.values()) + a.not_started
    assert total == 96
    assert "multi-lane falsifier" in a.text()


def test_every_failure_inside_is_located_and_replays():
    """Without the shield there are failures inside the assumptions (the entrants keep the rule; the ego does not):
    the report lists each one, as many as it counts, and each replays from its seed, stream, batch and row."""
    world = fl.LaneWorld(config=ShieldConfig(enabled=False), horizon_s=6.0)
    report = run(64, seed=3, batch_size=32, world=world)
    inside = report.counts["inside"]
    failed = report.failures
    assert len(failed) > 0
    assert sum(f["collision"] for f in failed) == inside["collisions"]
    assert sum(f["p_m_violation"] for f in failed) == inside["p_m_violations"]
    assert "failure inside: seed 3 stream 0 batch" in report.text()
    f = failed[-1]
    spec = fl.draw(np.random.default_rng([f["seed"], f["stream"], f["batch"]]), f["batch_size"], world.params)
    again = fl.simulate(fl.take(spec, [f["row"]]), world)
    assert again.inside[0] and again.collided[0] == f["collision"] and again.violated[0] == f["p_m_violation"]
