"""Issue 31, Gymnasium conventions: reward signs and env keyword arguments checked at construction, render_mode
"rgb_array", max_episode_steps in the spec, reset info with step's keys, a wrong action shape named."""

from __future__ import annotations

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import safelane.envs  # noqa: E402,F401  (registers the environment)
from safelane.envs import ENV_ID, LaneChangeEnv, LaneChangeVectorEnv, RewardConfig  # noqa: E402
from safelane.envs.render import EGO, FOLLOWER  # noqa: E402
from safelane.errors import InputError  # noqa: E402


@pytest.mark.parametrize("field", ["collision", "success", "progress"])
def test_reward_weights_are_non_negative(field):
    with pytest.raises(ValueError, match=rf"{field}\n.*greater than or equal to 0"):
        RewardConfig(**{field: -1.0})
    with pytest.raises(InputError, match=rf"reward: field '{field}' = -1: Input should be greater than or equal to 0"):
        LaneChangeEnv(reward={field: -1})


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(horizon_s=0), r"horizon_s \(episode length\) must be a number of seconds >= one control period"),
        (dict(horizon_s=-5.0), r"horizon_s .* got -5.0"),
        (dict(horizon_s="10"), r"horizon_s .* got '10' \(str\)"),
        (dict(shield="yes"), r"shield must be True or False; got 'yes'"),
        (dict(variant="CV_any"), r"variant must be one of CV_all, .*; got 'CV_any'"),
        (dict(p_v=2.0), r"p_v \(promise-violation rate per period\) must lie in \[0, 1\]"),
        (dict(n_leaders="3"), r"n_leaders must be a number or a sequence of numbers; got '3'"),
        (dict(decel=()), r"decel must be a number or a sequence of numbers"),
        (dict(scenario={"gap": (1.0, 2.0)}), r"scenario: gap=\(1.0, 2.0\): the lower bound must be >= 2.5 m"),
        (dict(scenario={"promise_decel": 9.0}), r"scenario.promise_decel=9.0 exceeds params.a_x_d=8.0"),
        (dict(sim_config={"horizon": 3}), r"sim_config: unknown field 'horizon'"),
        (dict(params={"p_m": -1}), r"params: field 'p_m' = -1"),
        (dict(traffic=42), r"traffic must be None, a registered traffic model's name"),
        (dict(render_mode="ansi"), r"render_mode must be None or one of \['rgb_array'\]; got 'ansi'"),
    ],
)
def test_bad_env_kwargs_are_refused_at_make(kwargs, match):
    with pytest.raises(InputError, match=match):
        gym.make(ENV_ID, **kwargs)


def test_vector_env_checks_its_kwargs_too():
    with pytest.raises(InputError, match="horizon_s"):
        LaneChangeVectorEnv(2, horizon_s=0)


def test_max_episode_steps_is_in_the_spec_and_follows_horizon_s():
    assert gym.make(ENV_ID).spec.max_episode_steps == 100
    env = gym.make(ENV_ID, horizon_s=2.0)
    assert env.spec.max_episode_steps == 20
    env.reset(seed=0)
    for k in range(20):
        *_, terminated, truncated, _ = env.step(np.zeros(2, np.float32))  # holds its lane: never completes
        assert terminated is False and truncated == (k == 19)
    again = gym.make(env.spec)
    assert again.spec.max_episode_steps == 20 and again.unwrapped.task.max_steps == 20
    assert gym.make(ENV_ID, max_episode_steps=5).spec.max_episode_steps == 5


def test_reset_info_has_steps_keys_that_apply():
    env = gym.make(ENV_ID)
    _, info0 = env.reset(seed=0)
    _, _, _, _, info1 = env.step(np.zeros(2, np.float32))
    assert set(info0) <= set(info1)
    assert info0 == {"intervened": False, "cost": 0.0, "crashed": False, "success": False}
    venv = LaneChangeVectorEnv(3)
    _, vinfo = venv.reset(seed=0)
    assert set(info0) <= set(vinfo) and vinfo["cost"].shape == (3,) and vinfo["_cost"].all()


def test_rgb_array_is_a_top_down_picture_of_the_scene():
    assert "rgb_array" in LaneChangeEnv.metadata["render_modes"]
    env = gym.make(ENV_ID, render_mode="rgb_array", n_leaders=1)
    env.reset(seed=0)
    first = env.render()
    assert first.ndim == 3 and first.shape[2] == 3 and first.dtype == np.uint8
    ego_rows = np.nonzero((first == EGO).all(-1).any(1))[0]
    assert ego_rows.size and (first == FOLLOWER).all(-1).any()  # the ego and F are drawn
    for _ in range(10):
        env.step(np.array([0.0, 1.5], np.float32))
    later = env.render()
    assert later.shape == first.shape
    moved = np.nonzero((later == EGO).all(-1).any(1))[0]
    assert moved.mean() < ego_rows.mean()  # toward the target lane: up the picture
    plain = gym.make(ENV_ID)
    plain.reset(seed=0)
    assert plain.render() is None  # no render_mode: nothing (Gymnasium's convention)


@pytest.mark.parametrize("action", [np.zeros(3), np.zeros((2, 2)), [1.0]])
def test_a_wrong_action_shape_is_named(action):
    env = gym.make(ENV_ID, disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(InputError, match=r"action must have shape \(2,\): \(a_x, a_y\) in m/s²; got shape"):
        env.step(action)


def test_a_wrong_vector_action_shape_is_named():
    venv = LaneChangeVectorEnv(3)
    venv.reset(seed=0)
    with pytest.raises(InputError, match=r"action must have shape \(3, 2\): .* got shape \(2, 2\)"):
        venv.step(np.zeros((2, 2)))
    with pytest.raises(InputError, match=r"action must be numbers"):
        venv.step([["a", "b"]] * 3)
