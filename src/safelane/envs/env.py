"""``LaneChangeEnv``: one lane change per episode, the agent as the nominal planner behind the shield.

Registered as ``safelane/LaneChange-v0`` (``gymnasium.make("safelane/LaneChange-v0", shield=False, ...)``).
Observation, action, reward, termination and ``info`` are documented in ``docs/envs.md`` and on the class.
"""

from __future__ import annotations

import warnings
from typing import Any, ClassVar

import numpy as np

from ..params import Params
from ..sim.config import SimConfig
from ..sim.scenario import ScenarioConfig
from ..sim.traffic import TrafficHooks
from ._gym import require_gymnasium
from .core import BEHAVIOUR_NAMES, LaneChangeTask, RewardConfig, ScenarioSampler

gym = require_gymnasium()
spaces = gym.spaces


def make_task(
    batch: int,
    *,
    variant: str = "CV_all",
    n_leaders=3,
    decel=(2.0, 6.0),
    scenario: ScenarioConfig | dict | None = None,
    p_v: float = 0.0,
    params: Params | None = None,
    sim_config: SimConfig | dict | None = None,
    shield: bool = True,
    traffic: TrafficHooks | None = None,
    reward: RewardConfig | dict | None = None,
    horizon_s: float | None = None,
) -> LaneChangeTask:
    """The task behind both environments from the ``make`` keyword arguments (see :class:`LaneChangeEnv`)."""
    if isinstance(reward, dict):
        reward = RewardConfig(**reward)
    if isinstance(params, dict):
        params = Params(**params)
    sampler = ScenarioSampler.build(variant, n_leaders, decel, scenario, p_v)
    limit = (params or Params()).a_x_d
    if sampler.decel[1] > limit:
        warnings.warn(
            f"decel up to {sampler.decel[1]:g} exceeds params.a_x_d={limit:g}: L(N+1) can brake harder than the "
            "worst case the shield assumes, so collisions are possible with the shield on",
            stacklevel=2,
        )
    return LaneChangeTask(
        batch, sampler, params=params, sim_config=sim_config, shield=shield, traffic=traffic, reward=reward,
        horizon_s=horizon_s,
    )


def spaces_of(task: LaneChangeTask):
    """``(observation_space, action_space)`` of one episode: the planners' feature map, ``(a_x, a_y)`` in m/s²."""
    lo, hi = task.action_bounds()
    obs = spaces.Box(-np.inf, np.inf, shape=(task.n_features,), dtype=np.float32)
    act = spaces.Box(lo.astype(np.float32), hi.astype(np.float32), dtype=np.float32)
    return obs, act


class LaneChangeEnv(gym.Env):
    """The ego changes lanes in front of a follower and behind a chain of leaders; the agent proposes
    accelerations, the shield (the safety supervisor) decides what is executed.

    Keyword arguments (all through ``gymnasium.make``):
        variant: the shield's information use (``"CV_all"``, ``"CV_follow"``, ``"CV_none"``, ``"No_agg_assess"``).
        n_leaders: ``N`` (connected leaders), or a sequence to draw it from uniformly per episode.
        decel: ``a_x_N+1_d``, the sudden braking of ``L(N+1)`` [m/s²], or ``(lo, hi)`` for ``U[lo, hi]``.
        scenario: a :class:`~safelane.sim.ScenarioConfig` (or a dict of its fields): speeds, gaps, promises,
            follower types.
        p_v: unexpected promise-violation probability per connected vehicle and period.
        params: :class:`~safelane.Params` (mechanical limits, geometry, ``p_m``).
        sim_config: :class:`~safelane.sim.SimConfig` (assessment, V2X emulation, sensor noise, ``horizon_s``).
        shield: ``True`` (default) runs the supervisor; ``False`` executes the agent's action as it is.
        traffic: :class:`~safelane.sim.traffic.TrafficHooks`: other behaviours for the leaders and ``F``.
        reward: :class:`RewardConfig` (or a dict of its weights).
        horizon_s: episode length [s] (default ``sim_config.horizon_s``, 10 s = 100 steps): ``truncated`` after it.

    Observation: ``Box(12,)`` float32, the neural planners' feature map
    (:data:`safelane.planners.features.FEATURE_NAMES`: ``p_y, v_y, v_x, gap_l, gap_f, dv_l, dv_f, l1_dv_1s …
    l1_dv_4s, f_connected``). Action: ``Box([-a_x_d, -a_y_m], [a_x_a, a_y_m])`` float32, ``(a_x, a_y)`` in m/s²
    (clipped to the box; a non-finite action is an invalid proposal, never executed: the shield hesitates or aborts,
    without it the ego holds ``(0, 0)``). ``terminated`` when the lane change completes or the ego collides;
    ``truncated`` at the horizon. ``info``: ``behaviour``
    (``"proceed"``, ``"hesitate"``, ``"abort"``), ``intervened``, ``nominal_action``, ``executed_action`` (the
    ego's mean acceleration over the period), ``cost`` (1.0 in the period a collision or the first ``p_m``
    violation of the episode happens), ``crashed``, ``success``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, **kwargs: Any):
        super().__init__()
        self.task = make_task(1, **kwargs)
        self.observation_space, self.action_space = spaces_of(self.task)
        self._started = False

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs = self.task.start([self.np_random])
        self._started = True
        return obs[0], {}

    def step(self, action):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        out = self.task.step(np.asarray(action, dtype=float).reshape(1, 2))
        info = {
            "behaviour": BEHAVIOUR_NAMES[int(out.behaviour[0])],
            "intervened": bool(out.intervened[0]),
            "nominal_action": out.nominal_action[0],
            "executed_action": out.executed_action[0],
            "cost": float(out.cost[0]),
            "crashed": bool(out.crashed[0]),
            "success": bool(out.success[0]),
        }
        terminated, truncated = bool(out.terminated[0]), bool(out.truncated[0])
        if terminated or truncated:
            self._started = False
        return out.obs[0], float(out.reward[0]), terminated, truncated, info
