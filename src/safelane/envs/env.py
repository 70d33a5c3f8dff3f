"""``LaneChangeEnv``: one lane change per episode, the agent as the nominal planner behind the shield.

Registered as ``safelane/LaneChange-v0`` (``gymnasium.make("safelane/LaneChange-v0", shield=False, ...)``).
Observation, action, reward, termination and ``info`` are documented in ``docs/envs.md`` and on the class.
"""

from __future__ import annotations

import numbers
import warnings
from typing import Any, ClassVar

import numpy as np

from ..errors import InputError
from ..params import Params
from ..sim.config import SimConfig
from ..sim.scenario import ScenarioConfig
from ..sim.traffic import TrafficHooks
from ..tolerances import SETTING_SLACK
from ._gym import require_gymnasium
from .core import BEHAVIOUR_NAMES, LaneChangeTask, RewardConfig, ScenarioSampler, check_action
from .render import task_frame

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
    """The task behind both environments from the ``make`` keyword arguments (see :class:`LaneChangeEnv`); a bad
    one raises :class:`~safelane.errors.InputError` naming it, its value and what is allowed."""
    from ..sim.inputs import as_model, check_settings

    reward = as_model(RewardConfig, reward, "reward")
    params = as_model(Params, params, "params")
    sim_config = as_model(SimConfig, sim_config, "sim_config")
    scenario = as_model(ScenarioConfig, scenario, "scenario")
    _check_kwargs(variant, n_leaders, decel, p_v, shield, traffic, horizon_s, params or Params())
    check_settings(params or Params(), sim_config or SimConfig(), scenario)
    try:
        sampler = ScenarioSampler.build(variant, n_leaders, decel, scenario, p_v)
    except ValueError as exc:
        raise InputError(str(exc)) from exc
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


def _check_kwargs(variant, n_leaders, decel, p_v, shield, traffic, horizon_s, params: Params) -> None:
    """The keyword arguments ``make`` passes on that no model validates (see :func:`make_task`)."""
    from ..planners.variants import VARIANT_NAMES

    if not isinstance(variant, str) or variant not in VARIANT_NAMES:
        raise InputError(f"variant must be one of {', '.join(VARIANT_NAMES)}; got {_got(variant)}", "variant")
    if not _is_real(p_v) or not 0.0 <= p_v <= 1.0:
        raise InputError(f"p_v (promise-violation rate per period) must lie in [0, 1]; got {_got(p_v)}", "p_v")
    if not isinstance(shield, bool | np.bool_):
        raise InputError(f"shield must be True or False; got {_got(shield)}", "shield")
    if traffic is not None and not (isinstance(traffic, str) or hasattr(traffic, "bind") or
                                    hasattr(traffic, "follower_wish")):  # fmt: skip
        raise InputError(f"traffic must be None, a registered traffic model's name, a TrafficModel or TrafficHooks; "
                         f"got {_got(traffic)}", "traffic")  # fmt: skip
    if horizon_s is not None and (not _is_real(horizon_s) or not np.isfinite(horizon_s) or
                                  horizon_s < params.dt - SETTING_SLACK):  # fmt: skip
        raise InputError(f"horizon_s (episode length) must be a number of seconds >= one control period "
                         f"params.dt={params.dt:g}; got {_got(horizon_s)}", "horizon_s")  # fmt: skip
    for name, value in (("n_leaders", n_leaders), ("decel", decel)):
        items = [value] if np.isscalar(value) else value
        try:
            ok = len(items) > 0 and all(_is_real(v) and np.isfinite(v) for v in items)
        except TypeError:
            ok = False
        if not ok:
            raise InputError(f"{name} must be a number or a sequence of numbers; got {_got(value)}", name)


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _got(value) -> str:
    return f"{value!r} ({type(value).__name__})"


def spaces_of(task: LaneChangeTask):
    """``(observation_space, action_space)`` of one episode: the planners' feature map, ``(a_x, a_y)`` in m/s²."""
    lo, hi = task.action_bounds()
    obs = spaces.Box(-np.inf, np.inf, shape=(task.n_features,), dtype=np.float32)
    act = spaces.Box(lo.astype(np.float32), hi.astype(np.float32), dtype=np.float32)
    return obs, act


#: ``info`` at ``reset``: the keys of ``step``'s info that apply before any action (no cost, crash, success or
#: intervention yet); ``behaviour``, ``nominal_action`` and ``executed_action`` describe an action, so only ``step``
#: has them.
RESET_INFO = {"intervened": False, "cost": 0.0, "crashed": False, "success": False}


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
        render_mode: ``None`` or ``"rgb_array"`` (``render()``: a top-down picture, :mod:`safelane.envs.render`).

    Every argument is checked here (:func:`make_task`): a bad one is an :class:`~safelane.errors.InputError` naming
    it. ``reset``'s info has the keys of ``step``'s that apply before an action (:data:`RESET_INFO`).

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

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, render_mode: str | None = None, **kwargs: Any):
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InputError(f"render_mode must be None or one of {self.metadata['render_modes']}; got "
                             f"{_got(render_mode)}", "render_mode")  # fmt: skip
        self.render_mode = render_mode
        self.task = make_task(1, **kwargs)
        self.observation_space, self.action_space = spaces_of(self.task)
        self._started = False

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs = self.task.start([self.np_random])
        self._started = True
        return obs[0], dict(RESET_INFO)

    def render(self):
        """``render_mode="rgb_array"``: a top-down picture of the scene, ``(H, W, 3)`` uint8 (:mod:`.render`)."""
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode: pass render_mode='rgb_array' to gymnasium.make")
            return None
        return task_frame(self.task)

    def step(self, action):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        out = self.task.step(check_action(action, (1, 2), accepted=(2,)))
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


def make_env(**kwargs: Any):
    """The registered entry point: a :class:`LaneChangeEnv` in a ``TimeLimit`` at its own horizon, so that
    ``env.spec.max_episode_steps`` is the episode length for any ``horizon_s`` (``gymnasium.make``'s own
    ``max_episode_steps=`` still adds a limit of its own on top)."""
    env = LaneChangeEnv(**kwargs)
    return gym.wrappers.TimeLimit(env, env.task.max_steps)


make_env.metadata = LaneChangeEnv.metadata  # what gymnasium.make reads for render_mode
