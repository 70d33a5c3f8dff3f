"""``LaneChangeVectorEnv``: ``num_envs`` lane changes in one batched closed loop (a native Gymnasium vector env).

One :class:`~safelane.sim.step.ClosedLoop` steps every sub-env at once; there is no per-env Python object. Auto-reset
is *same-step* (``metadata["autoreset_mode"] = AutoresetMode.SAME_STEP``): a sub-env whose episode ends in a step
returns the first observation of its next episode, and the last observation of the ended one is in
``info["final_obs"]`` (mask ``info["_final_obs"]``); ``info["final_info"]`` is the step's info. How the finished
rows are re-sampled and spliced into the running batch is explained in :mod:`safelane.envs.core`.

Sub-env ``i`` draws its scenarios from its own generator, seeded ``seed + i`` by ``reset(seed=seed)`` as a
``SyncVectorEnv`` of :class:`~safelane.envs.LaneChangeEnv` would: sub-env ``i`` meets the same scenarios as
``LaneChangeEnv`` reset with ``seed + i``, and given the same actions runs the same episodes (exactly in its first
episode; afterwards up to the rounding of the shifted clock, see ``tests/test_envs.py``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ..sim._stepper import steps_compiled
from ._gym import require_gymnasium
from .core import BEHAVIOUR_NAMES, check_action
from .env import RESET_INFO, make_task, spaces_of

gym = require_gymnasium()
from gymnasium.vector import AutoresetMode, VectorEnv  # noqa: E402
from gymnasium.vector.utils import batch_space  # noqa: E402

_BEHAVIOUR_LABELS = np.array([BEHAVIOUR_NAMES[k] for k in (0, 1, 2, -1)], dtype=object)  # index -1 -> completed


class LaneChangeVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~safelane.envs.LaneChangeEnv` (same keyword arguments) on the batched engine.

    ``info`` holds one array per key of the single env's info (``behaviour`` as an array of names; ``behaviour_code``
    as the supervisor's codes 0/1/2), each with its ``_key`` mask. Not supported here (the single env supports them):
    ``SimConfig.brake_start_s > 0`` and the V2X emulation (``v2x_loss``, ``v2x_latency_periods``), which read the
    absolute clock the sub-envs share; the own lane's ``L0`` and the actuation delay only where the compiled period
    steps them (each sub-env its own clock and commands in flight), never period by period in NumPy.
    """

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1024, **kwargs: Any):
        if int(num_envs) != num_envs or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer; got {num_envs!r}")
        self.task = make_task(int(num_envs), **kwargs)
        cfg = self.task.config
        if cfg.brake_start_s > 0.0 or cfg.v2x_loss > 0.0 or cfg.v2x_latency_periods > 0:
            raise ValueError(
                "LaneChangeVectorEnv needs sim_config.brake_start_s = 0 and perfect V2X (v2x_loss = 0, "
                "v2x_latency_periods = 0): its sub-envs share one clock; use LaneChangeEnv for those settings"
            )
        if cfg.own_lane or cfg.actuation_delay_s > 0.0:
            # Period by period the sub-envs share one clock and restarted rows are overwritten in the state: L0's
            # braking instant is on the episode's clock, and the commands in flight keep their aborting rows' plans.
            # The compiled period keeps each row's clock and queue (Stepper.splice): there they run.
            why = steps_compiled(self.task.sampler.draw_many([np.random.default_rng(0)]), cfg, self.task.traffic)
            if why:
                raise ValueError(
                    "LaneChangeVectorEnv runs sim_config.own_lane and actuation_delay_s > 0 on the compiled period "
                    f"only (each sub-env its own clock and commands in flight), which does not step these settings: "
                    f"{'; '.join(why)}; use LaneChangeEnv for them"
                )
        self.num_envs = int(num_envs)
        self.single_observation_space, self.single_action_space = spaces_of(self.task)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs: list[np.random.Generator] | None = None
        self._all = np.ones(self.num_envs, bool)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        super().reset(seed=seed if isinstance(seed, int) else None)
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset(seed=list) needs {self.num_envs} seeds; got {len(seeds)}")
        self._rngs = [np.random.default_rng(s) for s in seeds]
        info = {}
        for key, value in RESET_INFO.items():  # the single env's reset info, one array per key with its mask
            info[key], info["_" + key] = np.full(self.num_envs, value), self._all
        return self.task.start(self._rngs), info

    def step(self, actions):
        if self._rngs is None:
            raise RuntimeError("call reset() before step()")
        out = self.task.step(check_action(actions, (self.num_envs, 2)))
        done = out.terminated | out.truncated
        info = {
            "behaviour": _BEHAVIOUR_LABELS[out.behaviour],
            "behaviour_code": out.behaviour,
            "intervened": out.intervened,
            "nominal_action": out.nominal_action,
            "executed_action": out.executed_action,
            "cost": out.cost,
            "crashed": out.crashed,
            "success": out.success,
        }
        for key in list(info):
            info["_" + key] = self._all
        obs = out.obs
        if done.any():
            rows = np.flatnonzero(done)
            final_obs = np.empty(self.num_envs, object)  # (None where not done)
            for i, last in zip(rows.tolist(), obs[rows], strict=True):  # (one gather: ~2.5x faster than obs[i] each)
                final_obs[i] = last
            info["final_obs"], info["_final_obs"] = final_obs, done
            info["final_info"], info["_final_info"] = dict(info), done
            first = self.task.restart(rows)
            obs[rows] = first  # (obs is the step's own: final_obs holds copies of its rows)
        return obs, out.reward, out.terminated, out.truncated, info
