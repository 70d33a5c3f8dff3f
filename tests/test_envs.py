"""The Gymnasium environments (safelane.envs): API conformance, seeding, the shield's cost, vector/single parity."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the Gymnasium environments need the gym extra: pip install -e '.[gym]'")

from gymnasium.utils.env_checker import check_env  # noqa: E402

from safelane.envs import ENV_ID, LaneChangeEnv, LaneChangeVectorEnv  # noqa: E402
from safelane.envs.core import RewardConfig  # noqa: E402
from safelane.params import Params  # noqa: E402

INFO_KEYS = {"behaviour", "intervened", "nominal_action", "executed_action", "cost", "crashed", "success"}


def reckless(obs: np.ndarray) -> np.ndarray:
    """Full throttle while hovering inside the conflict zone just short of the lane boundary: without a shield
    the ego runs into L1's margin (features: column 0 is p_y, column 1 v_y)."""
    obs = np.atleast_2d(obs)
    prm = Params()
    a_y = np.clip(2.0 * (1.6 - obs[:, 0]) - 2.0 * obs[:, 1], -prm.a_y_m, prm.a_y_m)
    return np.stack([np.full(len(obs), prm.a_x_a), a_y], axis=1)


def fixed_actions(rows: int, steps: int, seed: int = 7) -> np.ndarray:
    """A reproducible sequence of random actions inside the box, ``(steps, rows, 2)``."""
    prm = Params()
    rng = np.random.default_rng(seed)
    return np.stack(
        [rng.uniform(-prm.a_x_d, prm.a_x_a, (steps, rows)), rng.uniform(-prm.a_y_m, prm.a_y_m, (steps, rows))], -1
    )


def test_import_safelane_does_not_import_gymnasium():
    code = "import sys, safelane, safelane.sim, safelane.planners; assert 'gymnasium' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_an_env_step_and_the_shield_do_not_import_pandas():
    """pandas (0.13–0.18 s to import here) loads with the first results table, not with an env or the shield."""
    code = (
        "import sys, numpy as np, gymnasium, safelane.envs\n"
        "from safelane.shield import Shield\n"
        "env = gymnasium.make('safelane/LaneChange-v0'); env.reset(seed=0); env.step(np.zeros(2, np.float32))\n"
        "assert 'pandas' not in sys.modules, 'pandas imported'\n"
        "from safelane.sim import paper_scenarios, simulate_batch\n"
        "simulate_batch(paper_scenarios('CV_all', 1, 3.0, 2, np.random.default_rng(0)))\n"
        "assert 'pandas' in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_missing_gymnasium_gives_an_install_hint():
    code = (
        "import sys; sys.modules['gymnasium'] = None\n"
        "try:\n    import safelane.envs\nexcept ImportError as e:\n    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    assert 'pip install "safelane[gym]"' in out


@pytest.mark.filterwarnings("ignore:.*(Box action spaces|Box observation space):UserWarning")
@pytest.mark.parametrize("shield", [True, False])
def test_check_env_passes(shield):
    check_env(LaneChangeEnv(shield=shield), skip_render_check=True)


def test_registered_and_made_through_gymnasium():
    env = gym.make(ENV_ID, shield=False, n_leaders=(1, 3), decel=4.0)
    assert isinstance(env.unwrapped, LaneChangeEnv)
    assert not env.unwrapped.task.config.shield.enabled
    env = gym.make("safelane.envs:" + ENV_ID)  # the module:id form, without importing safelane.envs first
    venv = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(venv, LaneChangeVectorEnv) and venv.num_envs == 3


def test_spaces_are_the_feature_map_and_the_mechanical_limits():
    from safelane.planners.features import FEATURE_NAMES

    env, prm = LaneChangeEnv(), Params()
    assert env.observation_space.shape == (len(FEATURE_NAMES),)
    np.testing.assert_array_equal(env.action_space.low, np.float32([-prm.a_x_d, -prm.a_y_m]))
    np.testing.assert_array_equal(env.action_space.high, np.float32([prm.a_x_a, prm.a_y_m]))


@pytest.mark.parametrize(
    ("n_leaders", "decel", "scenario"),
    [
        ((3,), (2.0, 6.0), None),
        ((0, 1, 3, 10), (2.0, 6.0), {"human_share": 0.5, "follower_connected_share": 0.5}),
        ((2,), 4.0, {"gap": (5, 9)}),
    ],
)
def test_batched_sampler_draws_the_paper_samplers_scenarios(n_leaders, decel, scenario):
    import dataclasses

    from safelane.envs.core import ScenarioSampler
    from safelane.envs.rows import stack_rows

    sampler = ScenarioSampler.build("CV_follow", n_leaders, decel, scenario, p_v=0.1)
    fast = sampler.draw_many([np.random.default_rng(s) for s in range(40)])
    reference = stack_rows([sampler.draw(np.random.default_rng(s)) for s in range(40)])
    for f in dataclasses.fields(fast):
        a, b = getattr(fast, f.name), getattr(reference, f.name)
        assert (a is None and b is None) or (np.array_equal(a, b) and a.dtype == b.dtype), f.name


@pytest.mark.parametrize("bits", ["PCG64", "PCG64DXSM", "Philox", "SFC64", "MT19937"])
@pytest.mark.parametrize(("n_leaders", "decel"), [((0, 1, 3, 10), (2.0, 6.0)), ((3,), 4.0)])
def test_batched_sampler_draws_the_same_with_every_bit_generator(bits, n_leaders, decel):
    """draw_many takes a row's draws as raw words where the generator's words are its 64-bit draws (MT19937's are
    not: the generator's own calls); the scenarios are draw's, and the generators are left in the same state."""
    import dataclasses

    from safelane.envs.core import ScenarioSampler
    from safelane.envs.rows import stack_rows

    sampler = ScenarioSampler.build("CV_all", n_leaders, decel, {"human_share": 0.5}, p_v=0.1)
    make = lambda s: np.random.Generator(getattr(np.random, bits)(s))  # noqa: E731
    fast_rngs, reference_rngs = [make(s) for s in range(30)], [make(s) for s in range(30)]
    for _ in range(3):  # several episodes: each draw continues its generator's stream
        fast = sampler.draw_many(fast_rngs)
        reference = stack_rows([sampler.draw(rng) for rng in reference_rngs])
        for f in dataclasses.fields(fast):
            a, b = getattr(fast, f.name), getattr(reference, f.name)
            assert (a is None and b is None) or (np.array_equal(a, b) and a.dtype == b.dtype), f.name
    assert [r.random() for r in fast_rngs] == [r.random() for r in reference_rngs]


def run_episode(env, actions, seed):
    obs, _ = env.reset(seed=seed)
    rows = [obs]
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        rows.append(np.append(obs, [reward, terminated, truncated]))
        if terminated or truncated:
            break
    return rows


def test_reset_seed_is_reproducible():
    actions = fixed_actions(1, 100)[:, 0]
    first = run_episode(LaneChangeEnv(), actions, seed=3)
    again = run_episode(LaneChangeEnv(), actions, seed=3)
    other = run_episode(LaneChangeEnv(), actions, seed=4)
    assert len(first) == len(again) and all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    assert not np.array_equal(first[0], other[0])


def test_info_keys_and_types():
    env = LaneChangeEnv()
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.float32([0.0, 1.0]))
    assert INFO_KEYS <= set(info)
    assert info["behaviour"] in {"proceed", "hesitate", "abort"}
    assert info["nominal_action"].shape == info["executed_action"].shape == (2,)
    assert info["cost"] in (0.0, 1.0) and isinstance(reward, float)


def test_horizon_truncates():
    env = LaneChangeEnv(horizon_s=0.5)
    env.reset(seed=0)
    flags = [env.step(np.float32([0.0, 0.0]))[2:4] for _ in range(5)]  # no lateral motion: never completes
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])


def test_shield_off_executes_the_action_and_never_intervenes():
    env = LaneChangeEnv(shield=False)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.float32([1.0, 0.5]))
    assert not info["intervened"] and info["behaviour"] == "proceed"
    np.testing.assert_allclose(info["executed_action"], [1.0, 0.5], atol=1e-9)


def rollout(venv, policy, steps):
    """Sum of cost, crashes, successes and ended episodes of ``policy(obs, t)`` in ``venv``."""
    obs, _ = venv.reset(seed=0)
    totals = dict.fromkeys(("cost", "crashed", "success", "episodes", "intervened"), 0)
    for t in range(steps):
        obs, _, terminated, truncated, info = venv.step(policy(obs, t))
        for key in ("cost", "crashed", "success", "intervened"):
            totals[key] += int(np.sum(info[key]))
        totals["episodes"] += int(np.sum(terminated | truncated))
    return totals


def test_shield_on_has_zero_cost_under_random_and_reckless_actions():
    venv = LaneChangeVectorEnv(128, decel=(2.0, 8.0), n_leaders=(0, 1, 3))
    rng = np.random.default_rng(0)
    random = rollout(venv, lambda obs, t: venv.action_space.sample() if t else rng.uniform(-1, 1, (128, 2)), 300)
    wild = rollout(venv, lambda obs, t: reckless(obs), 300)
    assert random["episodes"] > 300 and wild["episodes"] > 100
    assert random["cost"] == wild["cost"] == random["crashed"] == wild["crashed"] == 0
    assert wild["intervened"] > 0


def test_shield_off_reckless_policy_pays_cost():
    venv = LaneChangeVectorEnv(64, shield=False)
    totals = rollout(venv, lambda obs, t: reckless(obs), 100)
    assert totals["cost"] > 0 and totals["intervened"] == 0


def test_vector_env_matches_single_envs_on_the_same_seeds():
    """Sub-env i of a vector env reset with ``seed`` runs the episodes of a single env reset with ``seed + i``:
    the first episode exactly (same batch arithmetic), later ones from the same scenarios up to the rounding of the
    shared clock (1e-9 in the observations)."""
    n, steps, seed = 4, 160, 11
    actions = fixed_actions(n, steps)
    venv = LaneChangeVectorEnv(n, n_leaders=(1, 3), decel=(3.0, 6.0))
    vobs, _ = venv.reset(seed=seed)
    vec_rows = [[vobs[i]] for i in range(n)]
    episode = np.zeros(n, int)
    for t in range(steps):
        vobs, reward, terminated, truncated, info = venv.step(actions[t])
        for i in range(n):
            done = terminated[i] or truncated[i]
            last = info["final_obs"][i] if done else vobs[i]
            vec_rows[i].append((episode[i], last, reward[i], terminated[i], truncated[i]))
            if done:
                episode[i] += 1
                vec_rows[i].append((episode[i], vobs[i]))
    for i in range(n):
        env = LaneChangeEnv(n_leaders=(1, 3), decel=(3.0, 6.0))
        obs, _ = env.reset(seed=seed + i)
        np.testing.assert_array_equal(obs, vec_rows[i][0])
        ep, t, k = 0, 0, 1
        while t < steps:
            obs, reward, terminated, truncated, _ = env.step(actions[t, i])
            v_ep, v_obs, v_reward, v_term, v_trunc = vec_rows[i][k]
            assert v_ep == ep and (v_term, v_trunc) == (terminated, truncated)
            if ep == 0:
                np.testing.assert_array_equal(v_obs, obs)
                assert v_reward == reward
            else:
                np.testing.assert_allclose(v_obs, obs, rtol=0, atol=1e-9)
                assert abs(v_reward - reward) < 1e-9
            t, k = t + 1, k + 1
            if terminated or truncated:
                obs, _ = env.reset()
                ep += 1
                assert vec_rows[i][k][0] == ep
                np.testing.assert_array_equal(vec_rows[i][k][1], obs)  # the same new scenario
                k += 1
        assert ep >= 1  # every sub-env reset at least once


def test_vector_env_rejects_settings_that_read_the_shared_clock():
    with pytest.raises(ValueError, match="brake_start_s"):
        LaneChangeVectorEnv(2, sim_config={"brake_start_s": 1.0})


def test_reward_weights_are_validated_and_used():
    with pytest.raises(ValueError, match="comfort"):
        RewardConfig(comfort=-1.0)
    env = LaneChangeEnv(reward={"progress": 0.0, "comfort": 0.0, "time": 0.5, "intervention": 2.0})
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.float32([0.0, 0.0]))
    assert reward == -0.5 - 2.0 * info["intervened"]


@pytest.mark.rl
def test_ppo_example_smoke_with_the_shield():
    """The RL example's training function (``examples/ppo_shield.py``) for 512 steps: PPO trains in the vector env
    through the SB3 adapter, the counts come back, and with the shield no step had a cost."""
    pytest.importorskip("stable_baselines3", reason="the RL example needs the rl extra: pip install -e '.[rl]'")
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "ppo_shield.py"
    spec = importlib.util.spec_from_file_location("ppo_shield", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    result = example.train(shield=True, steps=512, envs=16, seed=0, eval_episodes=32)
    assert result["timesteps"] >= 512 and result["curve"]
    assert result["training"]["cost"] == 0.0 and result["training"]["collisions"] == 0
    for evaluation in result["evaluation"].values():
        assert evaluation["episodes"] >= 32
    assert result["evaluation"]["shield_on"]["collisions"] == 0
