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
