"""Registration of the environments with Gymnasium (on ``import safelane.envs`` and through the entry point)."""

from __future__ import annotations

ENV_ID = "safelane/LaneChange-v0"


def register_envs() -> None:
    """Register ``safelane/LaneChange-v0`` (single env and its native vector env); idempotent."""
    from ._gym import require_gymnasium

    gym = require_gymnasium()
    if ENV_ID in gym.registry:
        return
    gym.register(
        id=ENV_ID,
        # A factory, not the class: it wraps the env in a TimeLimit at its own horizon (horizon_s), so that
        # env.spec.max_episode_steps is the episode length whatever the keyword arguments.
        entry_point="safelane.envs.env:make_env",
        vector_entry_point="safelane.envs.vector:LaneChangeVectorEnv",
    )
