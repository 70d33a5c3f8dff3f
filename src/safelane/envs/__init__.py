"""Gymnasium environments (extra ``gym``): the lane change with the agent as the nominal planner behind the shield.

``import safelane.envs`` registers ``safelane/LaneChange-v0``; then ``gymnasium.make("safelane/LaneChange-v0",
shield=False)`` builds a :class:`LaneChangeEnv` and ``gymnasium.make_vec("safelane/LaneChange-v0", num_envs=1024,
vectorization_mode="vector_entry_point")`` a :class:`LaneChangeVectorEnv`. ``import safelane`` never imports
Gymnasium; this package needs it (``pip install "safelane[gym]"``). See ``docs/envs.md``.
"""

from __future__ import annotations

from ._gym import require_gymnasium

require_gymnasium()

from .core import BEHAVIOUR_NAMES, LaneChangeTask, RewardConfig, ScenarioSampler  # noqa: E402
from .env import LaneChangeEnv  # noqa: E402
from .registration import ENV_ID, register_envs  # noqa: E402
from .vector import LaneChangeVectorEnv  # noqa: E402

register_envs()

__all__ = [
    "BEHAVIOUR_NAMES",
    "ENV_ID",
    "LaneChangeEnv",
    "LaneChangeTask",
    "LaneChangeVectorEnv",
    "RewardConfig",
    "ScenarioSampler",
    "register_envs",
]
