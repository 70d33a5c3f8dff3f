"""Stable-Baselines3 adapter (extra ``rl``): :class:`~safelane.envs.LaneChangeVectorEnv` as an SB3 ``VecEnv``.

SB3 has its own vector-env interface (``reset() -> obs``, ``step -> (obs, rewards, dones, infos)`` with one info
dict per env and ``terminal_observation`` in it); this wraps the native Gymnasium vector env without a per-env
Python object in the simulation. The info dicts are built per step (SB3 needs them), which costs about a
microsecond per env.
"""

from __future__ import annotations

from typing import Any

import numpy as np

try:
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError('the SB3 adapter needs stable-baselines3: pip install "safelane[rl]"') from exc

from .vector import LaneChangeVectorEnv

#: Per-env info keys passed on to SB3 (and to its callbacks).
INFO_KEYS = ("cost", "crashed", "success", "intervened")


class SB3VecEnv(VecEnv):
    """``LaneChangeVectorEnv(num_envs, **kwargs)`` for Stable-Baselines3 (``PPO("MlpPolicy", SB3VecEnv(64))``)."""

    def __init__(self, num_envs: int = 64, seed: int | None = None, **kwargs: Any):
        self.env = LaneChangeVectorEnv(num_envs, **kwargs)
        super().__init__(num_envs, self.env.single_observation_space, self.env.single_action_space)
        self._seed = seed
        self._actions: np.ndarray | None = None

    def reset(self):
        seed, self._seed = self._seed, None
        obs, _ = self.env.reset(seed=seed)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, reward, terminated, truncated, info = self.env.step(self._actions)
        dones = terminated | truncated
        columns = {key: info[key].tolist() for key in INFO_KEYS}
        infos = [{key: columns[key][i] for key in INFO_KEYS} for i in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = info["final_obs"][i]
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, reward.astype(np.float32), dones, infos

    def seed(self, seed: int | None = None):
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def close(self) -> None:
        self.env.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.env, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.env, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        raise NotImplementedError("the sub-envs of LaneChangeVectorEnv are rows of one batch, not objects")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._get_indices(indices))
