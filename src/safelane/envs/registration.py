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
        entry_point="safelane.envs.env:LaneChangeEnv",
        vector_entry_point="safelane.envs.vector:LaneChangeVectorEnv",
    )
