"""The batched lane-change task behind the Gymnasium environments — no Gymnasium in here.

:class:`LaneChangeTask` drives one :class:`safelane.sim.step.ClosedLoop` over ``B`` episodes at once: the agent's
actions are the *nominal planner's proposals* (:class:`ActionPlanner`), the shield (the simulator's supervisor,
``SimConfig.shield.enabled``) decides what is executed, and the task turns the state change of one control period
into observations, rewards, costs and flags. :class:`~safelane.envs.LaneChangeEnv` is this task with ``B = 1``;
:class:`~safelane.envs.LaneChangeVectorEnv` is the same task over the whole batch.

Resets (the vector env's auto-reset): the rows that finished get fresh scenarios, sampled row by row from their own
generators exactly as a single env samples them, and a ``ClosedLoop`` over those rows alone gives their initial
state and first observation. On the compiled loop (:class:`~safelane.sim._stepper.Stepper`) the fresh rows' kernel
inputs and state are spliced into the running batch's arrays (:meth:`~safelane.sim._stepper.Stepper.splice`) from
episodes prepared ahead, each row's next ones drawn from its generator in their order (:mod:`.reserve`); each row
keeps its own clock, so a restarted row runs exactly the single env's episode. Period by period in NumPy a new
``ClosedLoop`` is built for the whole batch (its constant arrays), and the finished rows of the state are overwritten
by the initial state of their new scenarios (where the initial state has no record at all — the shield's memory of
the previous period — the rows' record is emptied, see :func:`.rows.vacate_rows`). That batch shares one clock, so a
row that restarts at batch time ``T`` runs its episode at ``T, T + dt, …``: its plan's clock is shifted by ``T`` and
nothing else in the closed loop reads the absolute time — as long as ``L(N+1)`` brakes from ``t = 0``
(``SimConfig.brake_start_s = 0``) and V2X is perfect, which the vector env therefore requires.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ..params import Params
from ..planners.base import Observation
from ..planners.features import FEATURE_NAMES, features, plan_steps
from ..safety._backend import ARRAY, jitable
from ..sim._fused import sense_scratch
from ..sim._stepper import Stepper, steps_compiled
from ..sim.config import SimConfig
from ..sim.scenario import ScenarioBatch
from ..sim.step import ClosedLoop
from ..sim.traffic import TrafficHooks
from .rows import replace_rows, shift_plan_clock
from .sampler import ScenarioSampler

#: The supervisor's behaviour codes (``info["behaviour"]``) and their names.
PROCEED, HESITATE, ABORT, COMPLETED = 0, 1, 2, -1
BEHAVIOUR_NAMES = {PROCEED: "proceed", HESITATE: "hesitate", ABORT: "abort", COMPLETED: "completed"}


class RewardConfig(BaseModel):
    """Weights of the reward; every term is per control period (``dt``).

    ``reward = progress·Δp_y/(w_l/2) + success·[completed safely] − collision·[crashed] − comfort·(a_x² + a_y²)·dt
    − time − cost·cost_t − intervention·[the shield intervened]``, where ``Δp_y`` is the ego's lateral progress over
    the period (the lane change completes when its centre crosses the lane boundary at ``w_l/2``, so the progress
    terms of a completed lane change add up to about ``progress``) and ``(a_x, a_y)`` is the *executed* acceleration
    (``info["executed_action"]``). The default weights are those of ``docs/envs.md``'s example. Every weight is
    ``>= 0``: the signs are in the formula (a bonus is added, a penalty subtracted).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    progress: float = Field(1.0, ge=0.0, description="Weight of the lateral progress toward the lane boundary.")
    success: float = Field(1.0, ge=0.0, description="Bonus when the lane change completes without a collision.")
    collision: float = Field(1.0, ge=0.0, description="Penalty on a collision of the ego (the episode ends; "
                             "subtracted, so a negative weight would reward crashing).")  # fmt: skip
    comfort: float = Field(0.01, ge=0.0, description="Penalty per (m/s²)²·s of executed acceleration.")
    time: float = Field(0.0, ge=0.0, description="Penalty per period (hurry).")
    cost: float = Field(0.0, ge=0.0, description="Penalty per unit of cost (0: leave it to a constrained method).")
    intervention: float = Field(
        0.0, ge=0.0, description="Penalty per period in which the shield hesitated or aborted instead of proceeding."
    )


    def weights(self) -> tuple[float, ...]:
        """The weights in :func:`outcome_core`'s order."""
        return self.progress, self.success, self.collision, self.comfort, self.time, self.cost, self.intervention


def outcome_core(xp, dt, y_boundary, w_progress, w_success, w_collision, w_comfort, w_time, w_cost, w_intervention,
                 vx0, y0, vy0, collided0, violated0, completed0, vx1, y1, vy1, collided1, violated1, completed1,
                 at_horizon, intervened):  # fmt: skip
    """What one period gives the agent, from the ego's state and flags before (``…0``) and after (``…1``) it: the
    reward (:class:`RewardConfig`), the executed acceleration ``(a_x, a_y)``, and ``crashed``, ``cost``,
    ``success``, ``terminated``, ``truncated``. Flags in and out as ``0.0``/``1.0`` (every flag of the state only
    ever turns on, so "it turned on" is a difference); one row (``xp = SCALAR``, the compiled envs) or a batch."""
    a_x = (vx1 - vx0) / dt
    a_y = (vy1 - vy0) / dt
    crashed = collided1 - collided0
    cost = xp.maximum(collided1, violated1) - xp.maximum(collided0, violated0)
    completed = completed1 - completed0
    success = completed * (1.0 - collided1)
    terminated = xp.maximum(completed, collided1)
    truncated = (1.0 - terminated) * at_horizon
    progress = (y1 - y0) / y_boundary
    reward = (w_progress * progress + w_success * success - w_collision * crashed - w_comfort * (a_x * a_x + a_y * a_y)
              * dt - w_time - w_cost * cost - w_intervention * intervened)  # fmt: skip
    return reward, a_x, a_y, crashed, cost, success, terminated, truncated


jitable(outcome_core)


class ActionPlanner:
    """A nominal planner whose proposal is whatever was set last: the agent's action, ``(B, 2)``."""

    def __init__(self, batch: int):
        self.a_x = np.zeros(batch)
        self.a_y = np.zeros(batch)

    def set(self, action: np.ndarray) -> None:
        self.a_x = np.ascontiguousarray(action[:, 0], dtype=float)
        self.a_y = np.ascontiguousarray(action[:, 1], dtype=float)

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        return self.a_x, self.a_y


@dataclasses.dataclass
class StepOutcome:
    """What one period gives, per row."""

    obs: np.ndarray  # (B, F) float32
    reward: np.ndarray  # (B,)
    terminated: np.ndarray
    truncated: np.ndarray
    behaviour: np.ndarray  # (B,) int
    intervened: np.ndarray
    nominal_action: np.ndarray  # (B, 2)
    executed_action: np.ndarray  # (B, 2)
    cost: np.ndarray  # (B,)
    crashed: np.ndarray
    success: np.ndarray


def check_action(action, shape: tuple[int, ...], accepted: tuple[int, ...] | None = None) -> np.ndarray:
    """``action`` as a float array of ``shape``; an :class:`~safelane.errors.InputError` naming the action, its
    shape and the expected one otherwise (``accepted``: the shape the caller takes, named in the message)."""
    if type(action) is np.ndarray and action.dtype.kind == "f" and action.shape in (shape, accepted):
        # nothing to check (the envs check, then hand the array to the task); a float32 policy's action converted
        return action.astype(np.float64, copy=False).reshape(shape)
    from ..errors import InputError

    want = accepted or shape
    try:
        arr = np.asarray(action, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"action must be numbers (a_x, a_y) in m/s² of shape {want}; got {action!r}",
                         "action") from exc  # fmt: skip
    if arr.size != math.prod(shape) or arr.shape not in (shape, want):
        text = np.array2string(np.asarray(arr), threshold=8, precision=3)
        raise InputError(f"action must have shape {want}: (a_x, a_y) in m/s²; got shape {arr.shape}: {text}",
                         "action")  # fmt: skip
    return arr.reshape(shape)


class LaneChangeTask:
    """``B`` lane-change episodes in one closed loop; the agent's actions are the nominal proposals."""

    def __init__(
        self,
        batch: int,
        sampler: ScenarioSampler,
        *,
        params: Params | None = None,
        sim_config: SimConfig | None = None,
        shield: bool = True,
        traffic: TrafficHooks | None = None,
        reward: RewardConfig | None = None,
        horizon_s: float | None = None,
    ):
        self.n = batch
        self.sampler = sampler
        self.params = params or Params()
        cfg = sim_config or SimConfig()
        if isinstance(cfg, dict):
            cfg = SimConfig(**cfg)
        self.config = cfg.model_copy(update={"supervised": bool(shield)})
        self.traffic = traffic
        self.reward_config = reward or RewardConfig()
        horizon = self.config.horizon_s if horizon_s is None else float(horizon_s)
        self.max_steps = max(1, round(horizon / self.params.dt))
        self.planner = ActionPlanner(batch)
        # The simulator's in-loop draws are keyed by (seed, scenario id, step): the ids are random per episode
        # (drawn from the episode's generator), so one fixed seed serves every episode.
        self.seed = 0
        self.loop: ClosedLoop | None = None
        self._batch: ScenarioBatch | None = None
        self._rngs: list[np.random.Generator] = []  # each row's generator (start)
        self._reserve = None  # the rows' next episodes on the compiled loop (reserve.Reserve; made at the first reset)
        self.state = None
        self.steps = np.zeros(batch, np.int64)
        self._bounds = tuple(bound[:, None] for bound in self.action_bounds())  # (per action column, see step)
        self._compiled: bool | None = None  # whether the loop runs compiled (decided at the first batch)

    @property
    def n_features(self) -> int:
        return len(FEATURE_NAMES)

    def action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        return np.array([-p.a_x_d, -p.a_y_m]), np.array([p.a_x_a, p.a_y_m])

    @property
    def batch(self) -> ScenarioBatch | None:
        """The running episodes' scenarios (the vector env's resets on the compiled loop put in when this is read:
        nothing in a step reads it)."""
        if self._reserve is not None:
            self._batch = self._reserve.scenarios(self._batch)
        return self._batch

    def start(self, rngs: Sequence[np.random.Generator]) -> np.ndarray:
        """Every row starts a fresh episode (row ``i`` drawn from ``rngs[i]``, and its later episodes too: see
        :meth:`restart`); the observations ``(B, F)``."""
        self._rngs, self._reserve = list(rngs), None
        self._batch = self.sampler.draw_many(self._rngs)
        self.loop = self._loop(self._batch)
        self.state = self.loop.initial_state()
        self.steps[:] = 0
        return self.observe()

    def restart(self, rows: np.ndarray) -> np.ndarray:
        """Rows ``rows`` start fresh episodes (each drawn from its row's generator), the others go on (see the module
        docstring for how the shared clock is handled); the fresh rows' first observations ``(len(rows), F)``. On the
        compiled loop the rows' next episodes are prepared ahead, in batches (:mod:`.reserve`: the same scenarios)."""
        if isinstance(self.loop, Stepper):  # the fresh rows' inputs and state spliced in; each row its own clock
            from .reserve import Reserve

            if self._reserve is None:
                self._reserve = Reserve(self, self._rngs)
            obs = self._reserve.restart(rows)
        else:
            fresh = self.sampler.draw_many([self._rngs[i] for i in rows.tolist()])
            _, start, obs = self.first_states(fresh)
            self._batch = replace_rows(self.batch, fresh, rows, self.n)
            self.loop = self._loop(self._batch)
            self.state = replace_rows(self.state, shift_plan_clock(start, self.state.t), rows, self.n)
        self.steps[rows] = 0
        return obs

    def first_states(self, fresh: ScenarioBatch):
        """The closed loop over the scenarios ``fresh`` (the task's settings), its initial state and the first
        observations ``(len(fresh), F)``."""
        first = ClosedLoop(fresh, self.seed, self.params, self.config, self.planner, self.traffic)
        start = first.initial_state()
        return first, start, features(first.observe(start), self.params).astype(np.float32)  # (the clock: no feature)

    def _step_compiled(self, proposal: np.ndarray) -> StepOutcome:
        """:meth:`step` on the compiled loop: the period, the observation and the outcome in one compiled call
        (``envs/_fast.py``: the same closed forms, bit for bit)."""
        from ._fast import OUTCOME, env_step_kernel

        loop, n = self.loop, self.n
        rows = self.state.rows  # advanced in place: the task keeps no state of the period before
        obs, outcome = np.empty((n, len(FEATURE_NAMES)), np.float32), np.empty((n, len(OUTCOME)))
        behaviour, finite = np.empty(n, np.int64), np.empty(n, np.bool_)
        self.steps += 1
        env_step_kernel(loop.prm_vec, loop.period_prm, tuple(loop.batch), tuple(rows), proposal, self._env_values,
                        self._view, self.steps, obs, outcome, behaviour, finite, self._sense)  # fmt: skip
        loop.check_finite(rows, finite)
        return StepOutcome(
            obs=obs,
            reward=outcome[:, 0],
            terminated=outcome[:, 6] > 0.5,
            truncated=outcome[:, 7] > 0.5,
            behaviour=behaviour,
            intervened=(behaviour == HESITATE) | (behaviour == ABORT),
            nominal_action=proposal,
            executed_action=outcome[:, 1:3],
            cost=outcome[:, 4],
            crashed=outcome[:, 3] > 0.5,
            success=outcome[:, 5] > 0.5,
        )

    def _loop(self, batch: ScenarioBatch):
        """The closed loop over ``batch``: compiled (:class:`~safelane.sim._stepper.Stepper`) where it covers the
        settings, else :class:`~safelane.sim.step.ClosedLoop` (the same interface, period by period)."""
        loop = ClosedLoop(batch, self.seed, self.params, self.config, self.planner, self.traffic)
        if self._compiled is None:  # (decided once: every batch comes from the same sampler and settings)
            self._compiled = not steps_compiled(batch, self.config, self.traffic)
        if not self._compiled:
            return loop
        prm = self.params
        self._env_values = np.array([prm.dt, prm.y_boundary, self.max_steps, *self.reward_config.weights()], float)
        self._view = (np.array(loop.shares_plan), np.array(loop.b.connected[:, 0]),  # (ours: restart splices rows)
                      np.array(plan_steps(prm.dt, self.config.l1_plan_steps), np.int64),
                      np.empty(self.config.l1_plan_steps))  # fmt: skip
        stepper = Stepper(loop)
        # the scratch of the shield's sensing box (None: off), allocated once: the rows' anchors live in their state
        sense = sense_scratch(stepper.prm_vec, batch.x.shape[1])
        self._sense = None if sense is None else tuple(sense)
        return stepper

    def observe(self) -> np.ndarray:
        return features(self.loop.observe(self.state), self.params).astype(np.float32)

    def step(self, action: np.ndarray) -> StepOutcome:
        """One control period with the agent's ``(B, 2)`` proposals (clipped to the action box)."""
        lo, hi = self._bounds
        # Clipped column by column (a (B, 2) array's inner loop of 2 would cost NumPy ~10x); NaN stays: an invalid one.
        proposal = np.empty((2, self.n))
        np.clip(check_action(action, (self.n, 2)).T, lo, hi, out=proposal)
        proposal = proposal.T
        if isinstance(self.loop, Stepper):
            return self._step_compiled(proposal)
        self.planner.set(proposal)
        before = self.state
        self.state, _, behaviour = self.loop.step(before)
        after = self.state
        self.steps += 1
        prm, rc = self.params, self.reward_config
        flag = lambda a: a.astype(float)  # noqa: E731
        reward, a_x, a_y, crashed, cost, success, terminated, truncated = outcome_core(
            ARRAY, prm.dt, prm.y_boundary, *rc.weights(), before.ego[2], before.ego[1], before.ego[3],
            flag(before.collided), flag(before.violated), flag(before.completed), after.ego[2], after.ego[1],
            after.ego[3], flag(after.collided), flag(after.violated), flag(after.completed),
            flag(self.steps >= self.max_steps), flag((behaviour == HESITATE) | (behaviour == ABORT)),
        )  # fmt: skip
        return StepOutcome(
            obs=self.observe(),
            reward=reward,
            terminated=terminated > 0.5,
            truncated=truncated > 0.5,
            behaviour=np.asarray(behaviour, np.int64),
            intervened=(behaviour == HESITATE) | (behaviour == ABORT),
            nominal_action=proposal,
            executed_action=np.stack([a_x, a_y], axis=1),
            cost=cost,
            crashed=crashed > 0.5,
            success=success > 0.5,
        )
