"""Episodes of the three hosts exported to CommonRoad and refereed by the drivability checker: a small set each,
collisions from unshielded runs among them (the full count: benchmarks/bench_commonroad_referee.py)."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.integrations.commonroad import INSTALL_HINT

pytest.importorskip("commonroad", reason=f"commonroad-io is not installed: {INSTALL_HINT}")
pytest.importorskip("commonroad_dc", reason=f"the drivability checker is not installed: {INSTALL_HINT}")

from safelane import Params
from safelane.integrations.commonroad import EGO_ID, read_commonroad, write_commonroad
from safelane.integrations.commonroad_hosts import simulator_episodes
from safelane.integrations.commonroad_referee import referee_episode
from safelane.planners.adversarial import RecklessMerge
from safelane.sim import SimConfig, paper_scenarios, simulate_batch


def unshielded_merges(n: int = 24, seed: int = 1):
    """``n`` scenarios of the paper's sampler (N = 3, a = 6) with an L0 in the ego's lane, driven without the shield
    by reckless merges of random strength (about half of them collide)."""
    rng = np.random.default_rng(seed)
    batch = paper_scenarios("CV_all", 3, 6.0, n, np.random.default_rng(seed))
    nominal = RecklessMerge(a_x=rng.uniform(-4.0, 3.0, n), lateral_gain=rng.uniform(0.2, 1.0, n))
    return batch, SimConfig(supervised=False, own_lane=True), nominal


def test_simulator_episodes_are_the_simulators_runs():
    """The adapter's loop is the simulator's: its results table equals simulate_batch's, and each record's verdict
    is the table's collision column."""
    batch, config, nominal = unshielded_merges()
    episodes, table = simulator_episodes(batch, config=config, nominal=nominal)
    reference = simulate_batch(batch, config=config, nominal=nominal).table
    for column in ("collision", "completed", "safety_violation", "own_lane_collision", "n_hesitate"):
        np.testing.assert_array_equal(table[column].to_numpy(), reference[column].to_numpy(), err_msg=column)
    assert [e.collided for e in episodes] == table["collision"].tolist()
    prm = Params()
    ep = episodes[0]
    assert ep.names[:3] == ("ego", "F", "L1") and ep.names[-1] == "L0" and len(ep.names) == 1 + 5 + 1
    assert ep.steps == round(config.horizon_s / prm.dt) + 1 and ep.dt == prm.dt
    np.testing.assert_array_equal(ep.length, prm.vehicle_length)
    np.testing.assert_array_equal(ep.width, prm.vehicle_width)
    np.testing.assert_array_equal(ep.y[1:-1], prm.lane_width)  # the target lane's vehicles
    np.testing.assert_array_equal(ep.y[-1], 0.0)  # L0 in the ego's lane
    assert ep.y[0, 0] == 0.0 and ep.speed[0, 0] == pytest.approx(batch.ego_vx[0])
    assert ep.x[1, 0] == batch.x[0, 0] and ep.speed[2, 0] == batch.v[0, 1]


def test_the_checker_agrees_with_the_simulator_on_shielded_and_unshielded_runs(tmp_path):
    batch, config, nominal = unshielded_merges()
    unshielded, _ = simulator_episodes(batch, config=config, nominal=nominal)
    shielded, _ = simulator_episodes(paper_scenarios("CV_all", 1, 8.0, 8, np.random.default_rng(2)))
    episodes = unshielded + shielded
    collided = sum(e.collided for e in episodes)
    assert 6 <= collided <= len(unshielded) - 6  # collisions and clear episodes both, from the unshielded runs
    assert not any(e.collided for e in shielded)
    for ep in episodes:
        scenario, _ = read_commonroad(write_commonroad(tmp_path / f"{ep.host}-{ep.episode_id}.xml", ep))
        verdict, agreement = referee_episode(ep, scenario)
        assert agreement.agree, (ep.episode_id, agreement)
        assert verdict.collision is ep.collided
        if verdict.collision:
            assert all(EGO_ID < p < EGO_ID + len(ep.names) for p in verdict.partners)


def reckless(env):
    """Full authority toward the target lane (benchmarks/highway_campaign.py's policy)."""
    prm, ego = env.params, env.ego
    y, vy = (float(z) for z in env.frame.y(ego.position[1], ego.lateral_speed))
    return np.array([prm.a_x_a, np.clip(2.0 * (prm.lane_width - y) - 2.5 * vy, -prm.a_y_m, prm.a_y_m)])


def test_highway_env_episodes_are_refereed(tmp_path):
    pytest.importorskip("highway_env", reason='highway-env is not installed: pip install "safelane[highway]"')
    import gymnasium as gym

    from safelane.integrations.commonroad_hosts import highway_episode
    from safelane.integrations.highway import SCENE_ENV_ID, SafeLaneShield

    config = {"observation": {"type": "LidarObservation"}, "decel": [8.0], "duration": 4}
    kinds = []
    for shield, seeds in ((False, (0, 1, 2)), (True, (0,))):
        env = SafeLaneShield(gym.make(SCENE_ENV_ID, config=config), shield=shield)
        for seed in seeds:
            ep = highway_episode(env, reckless, seed)
            assert ep.host == "highway-env" and ep.names[0] == "ego" and "L1" in ep.names
            assert ep.lane_width == 4.0 and ep.lanes_y[ep.target_lane] > ep.y[0, 0]  # mirrored: the target is left
            np.testing.assert_array_equal(ep.length, 5.0)
            scenario, _ = read_commonroad(write_commonroad(tmp_path / f"hw-{shield}-{seed}.xml", ep))
            _, agreement = referee_episode(ep, scenario)
            kinds.append((shield, agreement.kind))
            assert agreement.agree or "predicted contact" in agreement.reason, agreement
    assert (False, "both collide") in kinds and (True, "both clear") in kinds


@pytest.fixture(scope="module")
def sumo_world():
    pytest.importorskip("libsumo", reason="libsumo is not installed: pip install 'safelane[sumo]'")
    from safelane.integrations.commonroad_hosts import recording_world_class

    world = recording_world_class()(Params())
    yield world
    world.close()


def test_sumo_episodes_are_refereed(sumo_world, tmp_path):
    from safelane.integrations.commonroad_hosts import sumo_episodes
    from safelane.integrations.sumo import SumoRunner, reckless, sumo_scenarios

    scenarios = sumo_scenarios(1, 6.0, 3, seed=0, own_share=0.5)
    runner = SumoRunner(Params(), policy=reckless, world=sumo_world)
    episodes = sumo_episodes(runner, scenarios, shielded=False) + sumo_episodes(runner, scenarios[:1])
    assert [e.shielded for e in episodes] == [False] * 3 + [True]
    assert sum(e.collided for e in episodes[:3]) >= 2 and not episodes[3].collided
    for ep in episodes:
        assert ep.host == "sumo" and set(ep.names) >= {"ego", "F", "L1", "L2"}
        assert ep.lanes_y[1] - ep.lanes_y[0] == pytest.approx(Params().lane_width)
        np.testing.assert_allclose(ep.heading[ep.present], 0.0, atol=1e-9)  # straight road, bodies along it
        scenario, _ = read_commonroad(write_commonroad(tmp_path / f"sumo-{ep.episode_id}.xml", ep))
        verdict, agreement = referee_episode(ep, scenario)
        assert agreement.agree, agreement
        if ep.collided:
            assert EGO_ID + ep.names.index(ep.collision_partner) in verdict.partners
