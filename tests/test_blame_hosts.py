"""The blame rule (safelane.blame) in the hosts, each with its own referee of the collision: highway-env's
``crashed`` flag for ``info["crash_blame"]``, SUMO's collision list for the episode's blame, the simulator's collision
flags for its table's blame columns."""

from __future__ import annotations

import numpy as np
import pytest


# ---------------------------------------------------------------- highway-env
def highway_scene(other_dx: float, other_dv: float, other_lane: str):
    """The lane-change scene with every other vehicle removed and one hand-placed highway-env ``Vehicle`` (constant
    speed, no control) ``other_dx`` ahead of the ego (negative: behind), ``other_dv`` faster, in the ego's own lane or
    its target lane. The wrapper runs unshielded: the test's actions go to the ego as they are."""
    pytest.importorskip("highway_env", reason="needs the highway extra: pip install -e '.[highway]'")
    import gymnasium as gym
    from highway_env.vehicle.kinematics import Vehicle

    from safelane.integrations.highway import SCENE_ENV_ID, SafeLaneShield

    env = SafeLaneShield(gym.make(SCENE_ENV_ID, config={"observation": {"type": "LidarObservation"},
                                                        "duration": 20}), shield=False)  # fmt: skip
    env.reset(seed=0)
    road, ego = env.env.unwrapped.road, env.ego
    lane = env.original_lane if other_lane == "own" else env.target_lane
    y = road.network.get_lane(lane).position(0.0, 0.0)[1]
    other = Vehicle(road, np.array([ego.position[0] + other_dx, y]), 0.0, ego.speed + other_dv)
    road.vehicles[:] = [ego, other]
    env.reset_blame()  # the scene changed under the wrapper: follow the new vehicles from now on
    return env, other


def drive(env, action, steps=150):
    for _ in range(steps):
        info = env.step(np.asarray(action, float))[4]
        if info["crashed"]:
            return info
        assert info["crash_blame"] is None
    raise AssertionError("no crash: the scene is wrong")


def test_highway_rammed_from_behind_is_the_others():
    """The ego cruises in its lane; a vehicle 60 m behind, 10 m/s faster, never brakes: highway-env flags the crash,
    the rule says the other (the rear one, which was at a safe distance once)."""
    env, other = highway_scene(-60.0, 10.0, "own")
    info = drive(env, [0.0, 0.0])
    assert other.crashed and info["crash_blame"] == "other"
    assert info["crash"]["blame_clause"] == "longitudinal" and info["crash"]["kind"].startswith("it ran into")
    assert env.step(np.zeros(2))[4]["crash_blame"] == "other"  # kept while the ego stays crashed


def test_highway_unshielded_close_cut_in_is_the_egos():
    """The unshielded ego swerves at full lateral acceleration into the target lane with a vehicle 6 m behind it
    there, 3 m/s faster: the crash is the ego's (it moved laterally while longitudinally unsafe)."""
    env, other = highway_scene(-6.0, 3.0, "target")
    info = drive(env, [0.0, env.params.a_y_m])
    assert other.crashed and info["crash_blame"] == "ego"
    assert info["crash"]["blame_clause"] == "lateral"


def test_highway_no_crash_no_blame():
    env, _ = highway_scene(60.0, 0.0, "target")
    for _ in range(20):
        info = env.step(np.zeros(2))[4]
        assert not info["crashed"] and info["crash_blame"] is None


# ---------------------------------------------------------------- SUMO's record (pure data; the SUMO run is in
# tests/test_integration_sumo.py, which holds the process's one SUMO)
def test_sumo_state_log_rear_end_by_the_follower():
    """A hand-made record: the ego in lane 0 at 20 m/s, "F" 60 m behind at 30 m/s in the same lane; SUMO's entry
    names F the collider: the rule says F (the rear vehicle, safe once), and the victim's blame is "collider"."""
    from safelane import Params
    from safelane.baselines.rss import RssParams
    from safelane.integrations.sumo_episode import EpisodeResult, StateLog

    prm = Params()
    log = StateLog(["ego", "F", "L1"], 5.0, 2.0, RssParams.matched(prm))
    t_hit = None
    for k in range(80):
        t = round(0.1 * k, 10)
        x = np.array([100.0 + 20.0 * t, 40.0 + 30.0 * t, 300.0 + 20.0 * t])
        log.record(t, x, [0.0, 0.0, 3.5], [20.0, 30.0, 20.0], [0.0, np.nan, np.nan])
        if t_hit is None and x[0] - x[1] < 5.0:
            t_hit = t
    entries = [{"collider": "F", "victim": "ego", "t": t_hit}]
    log.classify(entries)
    assert entries[0]["responsible"] == "F" and entries[0]["blame"] == "collider"
    assert entries[0]["blame_clause"] == "longitudinal" and entries[0]["blame_t"] < t_hit
    res = EpisodeResult(0, 1, 4.0, False, 0.0, "paper", True, collided=True, collisions=entries)
    assert res.collision_blame == "other" and res.results_row("x")["collision_blame"] == "other"


# ---------------------------------------------------------------- the simulator
def test_simulator_f_that_ignores_the_ego_is_responsible_for_its_collisions():
    """The simulator's own collision flags as the referee: an F that ignores the ego hits it (paper preset, CV_all);
    the ego entered the target lane at RSS's safe distance (this world's limits), so each collision is F's, by the
    longitudinal clause, and the summary puts none on the ego; the other columns are those of a run without blame."""
    from safelane.sim import simulate
    from safelane.sim.preset import load_preset

    cfg = load_preset("paper").sim.model_copy(update={"follower_ignores_ego": True})
    kw = dict(preset="paper", config=cfg)
    with_blame = simulate("CV_all", 3, 4.0, 40, 0, blame=True, **kw)
    plain = simulate("CV_all", 3, 4.0, 40, 0, **kw).table
    table = with_blame.table
    assert table["collision"].sum() > 10, "no collisions: the scenario is wrong"
    hits = table[table["collision"]]
    assert set(hits["collision_partner"]) == {"F"} and set(hits["collision_blame"]) == {"other"}
    assert set(hits["collision_blame_clause"]) == {"longitudinal"} and (hits["collision_blame_t"] >= 0).all()
    assert set(table.loc[~table["collision"], "collision_blame"]) <= {""}
    assert (table["pm_blame"] != "").sum() == table["safety_violation"].sum()
    s = with_blame.summary()
    assert s["collision_ego_rate"].iloc[0] == 0.0 and s["collision_rate"].iloc[0] > 0.25
    assert list(s.columns).index("collision_ego_rate") == list(s.columns).index("collision_hi") + 1
    pd = pytest.importorskip("pandas")
    pd.testing.assert_frame_equal(table[plain.columns], plain)


def test_simulator_ego_responsible_when_it_cuts_in_too_close():
    """Unshielded (the expert's proposal as it is) against an F that ignores the ego: some lane changes start inside
    RSS's safe distance to F (this world's limits) — those collisions are the ego's, by the lateral clause — the
    others F's, by the longitudinal one. With ad-rss's own parameters (ρ 1 s and 2 s: far longer distances, through
    the loop's ``blame=RssParams()``) every collision with F is the ego's."""
    from safelane.baselines.rss import RssParams
    from safelane.params import Params
    from safelane.planners.base import ExpertPlanner
    from safelane.sim import paper_scenarios, simulate_batch
    from safelane.sim.config import SimConfig
    from safelane.sim.step import ClosedLoop

    cfg = SimConfig(follower_ignores_ego=True, shield={"enabled": False})
    batch = paper_scenarios("CV_all", 3, 4.0, 30, np.random.default_rng(0))
    hits = simulate_batch(batch, 0, config=cfg, blame=True).table.query("collision")
    pairs = set(zip(hits["collision_blame"], hits["collision_blame_clause"], strict=True))
    assert pairs == {("ego", "lateral"), ("other", "longitudinal")}, pairs
    loop = ClosedLoop(batch, 0, Params(), cfg, ExpertPlanner(), blame=RssParams())
    state = loop.initial_state()
    for _ in range(round(cfg.horizon_s / Params().dt)):
        state = loop.step(state)[0]
    ev = state.blame.collision
    hit = ev.partner == 0
    assert hit.sum() == len(hits) and set(ev.responsible[hit].tolist()) == {1} and set(ev.clause[hit].tolist()) == {3}


def test_simulator_compiled_loop_gets_the_same_blame_columns():
    """A run the compiled loop takes (64 scenarios, the expert planner, default settings) with blame=True: the same
    blame columns as the period-by-period run of the same batch (SAFELANE_NO_FUSED=1), and the same table."""
    import os

    from safelane.sim import paper_scenarios, simulate_batch
    from safelane.sim.preset import load_preset

    prm = load_preset("paper").params
    batch = paper_scenarios("CV_all", 3, 6.0, 64, np.random.default_rng(3))
    fused = simulate_batch(batch, 0, params=prm, blame=True)
    os.environ["SAFELANE_NO_FUSED"] = "1"
    try:
        steps = simulate_batch(batch, 0, params=prm, blame=True)
    finally:
        del os.environ["SAFELANE_NO_FUSED"]
    assert fused.engine == "compiled loop" and steps.engine == "period by period"
    pd = pytest.importorskip("pandas")
    pd.testing.assert_frame_equal(fused.table, steps.table[fused.table.columns])


def test_simulator_rerun_for_blame_checks_the_compiled_outcomes():
    """The rerun of the compiled loop's event rows must reproduce them: a table that claims a collision the
    scenario does not have is refused (the guard runs the rows again, so this exercises the rerun too)."""
    from safelane.params import Params
    from safelane.planners.base import ExpertPlanner
    from safelane.sim import paper_scenarios
    from safelane.sim.config import SimConfig
    from safelane.sim.engine import _blame_again
    from safelane.sim.results import results_table
    from safelane.sim.step import ClosedLoop

    batch = paper_scenarios("CV_all", 1, 6.0, 4, np.random.default_rng(3))
    sim = ClosedLoop(batch, 0, Params(), SimConfig(), ExpertPlanner(), blame=True)
    state = sim.initial_state()
    for _ in range(50):
        state = sim.step(state)[0]
    table = results_table(sim.b, sim.finish(state)).drop(columns=["collision_blame"])
    assert len(_blame_again(table, sim, 50)) == 4
    table.loc[1, "collision"] = True
    with pytest.raises(RuntimeError, match="disagrees with the compiled loop"):
        _blame_again(table, sim, 50)
