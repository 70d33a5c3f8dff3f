"""The compiled closed loop's period from Python: :class:`Stepper` (:class:`~.step.ClosedLoop`'s interface, the state a
value, :class:`StepState`) over ``_fast_loop.step_kernel`` and ``finish_kernel``, for runs whose nominal planner, trace
or recorded observations keep the whole loop (:mod:`._fused`) from them, and for the envs. :func:`steps_compiled` says
where it steps a batch. The kernels' inputs and dispatch are :mod:`._fused`'s; this module only steps them."""

from __future__ import annotations

import dataclasses

import numpy as np

from ._fused import (
    BATCH_LAST,
    BATCH_SHARED,
    BY_ID,
    LOOP_ONLY,
    _non_finite,
    _own,
    _slow,
    _state,
    kernel_inputs,
    reasons,
    rows_of,
    sense_scratch,
    setting,
)


@dataclasses.dataclass(frozen=True)
class StepState:
    """A batch's state in the compiled loop (the arrays of ``_fast_rows.Rows``, the batch first, so that the envs'
    row surgery ``envs/rows.replace_rows`` replaces rows), with the :class:`~.step.SimState` fields the envs and
    :meth:`~.step.ClosedLoop.observe` read as views: ``ego``, ``x``, ``v``, ``acc``, ``t`` (``(B,)``: each row
    its own clock), ``completed``, ``collided``, ``violated``, ``l0`` (``None``: no own lane)."""

    rows: tuple

    @property
    def ego(self):
        rf = self.rows.rf
        return rf[:, 0], rf[:, 1], rf[:, 2], rf[:, 3]

    x = property(lambda self: self.rows.x)
    v = property(lambda self: self.rows.v)
    acc = property(lambda self: self.rows.acc)
    t = property(lambda self: self.rows.rf[:, 4])
    completed = property(lambda self: self.rows.rb[:, 7])
    collided = property(lambda self: self.rows.rb[:, 0])
    violated = property(lambda self: self.rows.rb[:, 1])

    @property
    def l0(self):
        rows = self.rows
        return (rows.own_x, rows.own_v) if np.isfinite(rows.own_x[:, 0]).any() else None


class Stepper:
    """:class:`~.step.ClosedLoop`'s interface for stepping (``initial_state``, ``step``, ``observe``) on the compiled
    period (``_fast_loop.step_kernel``): the envs' loop, where :func:`steps_compiled` says it runs, and
    ``simulate_batch``'s, which steps in place (:meth:`advance`). The nominal
    proposals are the planner's (the envs' ``ActionPlanner``: the agent's actions), passed to the kernel as they are;
    the state's arithmetic is the closed loop's, bit for bit (``tests/test_env_compiled.py``)."""

    def __init__(self, sim, shared_clock: bool = False):
        self.sim = sim
        self.prm_vec, self.period_prm, self.batch = kernel_inputs(sim)
        self.shared_clock = shared_clock  # every row started together: observations carry one time, as ClosedLoop's
        self.initial_safe = None
        self.spliced = False  # rows of other scenarios spliced in (splice): sim no longer describes the batch

    def initial_state(self) -> StepState:
        self._whole("initial_state")
        start = self.sim.initial_state()
        self.initial_safe = start.initial_safe
        return self.state_of(start)

    @staticmethod
    def state_of(start) -> StepState:
        """A :class:`~.step.SimState` at the start of a run (:meth:`~.step.ClosedLoop.initial_state`) as the
        compiled loop's state."""
        return StepState(rows_of(start))

    def observe(self, s: StepState):
        self._whole("observe")
        obs = self.sim.observe(s)
        return dataclasses.replace(obs, t=float(s.t[0])) if self.shared_clock else obs

    def finish(self, s: StepState):
        """:meth:`~.step.ClosedLoop.finish`: the state after the last period with the monitor's view of that period,
        as the fields :func:`~.results.results_table` reads (the compiled loop's, :func:`_state`)."""
        from ._fast_loop import finish_kernel

        self._whole("finish")
        rows = self.rows_after(s)
        finish_kernel(self.prm_vec, self.period_prm, self.batch, rows,
                      sense_scratch(self.prm_vec, rows.x.shape[1]))
        return _state(dict(
            t_complete=rows.rf[:, 5], min_gap_f=rows.rf[:, 6], min_gap_l1=rows.rf[:, 7], min_lane_ratio=rows.rf[:, 8],
            first_collaborative_s=rows.st[:, 1], breach_first_s=rows.st[:, 2], completed=rows.rb[:, 7],
            collided=rows.rb[:, 0], violated=rows.rb[:, 1], leader_collided=rows.rb[:, 2],
            leader_violated=rows.rb[:, 3], aggressive=rows.sk[:, 2], counts=rows.ri[:, :3], n_invalid=rows.ri[:, 3],
            breach_flags=rows.sk[:, 5:10], initial_safe=self.initial_safe, slow_delay_s=rows.st[:, 7],
            slow_missed=rows.sk[:, 10], slow_aggressive=rows.sk[:, 11], min_gap_l0=rows.rf[:, 9], own_x=rows.own_x,
            own_v=rows.own_v, l0_collided=rows.rb[:, 5], l0_violated=rows.rb[:, 6], own_pair_collided=rows.rb[:, 8],
        ), _slow(self.sim), _own(self.sim))  # fmt: skip

    def step(self, s: StepState):
        """:meth:`~.step.ClosedLoop.step`: the nominal planner's proposals on this state's observation, one period."""
        obs = self.observe(s)
        new, behaviour = self.step_with(s, *self._proposal(obs))
        return new, obs, behaviour

    def _proposal(self, obs) -> list[np.ndarray]:
        """The nominal planner's ``[a_x, a_y]`` on ``obs``, checked as the shield checks it (errors name the
        planner)."""
        from ..shield.proposals import proposal_arrays

        return proposal_arrays(self.sim.planner_name, self.sim.nominal(obs, self.sim.prm), len(self.sim.b))

    def step_with(self, s: StepState, a_x, a_y):
        """One period with the nominal proposals ``a_x``, ``a_y`` ``(B,)`` given (a planner that does not read the
        observation: the envs' actions): ``(state', behaviour)``; ``s`` is not changed."""
        rows = self.rows_after(s)
        return StepState(rows), self._period(rows, a_x, a_y)

    def advance(self, s: StepState):
        """:meth:`step` in place: ``s``'s rows become the state after the period, and ``(s, obs, behaviour)`` is
        returned — for a loop that keeps no earlier state (``engine.simulate_batch``'s), which then does not copy the
        whole state every period as :meth:`step` does. The observation owns its arrays (:meth:`observe_owned`), so the
        planner, a trace or the recorded observations see what :meth:`step` would have shown them."""
        obs = self.observe_owned(s)
        return s, obs, self._period(s.rows, *self._proposal(obs))

    def observe_owned(self, s: StepState):
        """:meth:`observe` with every array the observation shares with ``s``'s rows copied (the rest, e.g. the
        batch's own arrays or ``l1_plan``, made anew each period, as they are): an observation that stays what it was
        while :meth:`advance` steps the rows in place."""
        obs = self.observe(s)
        held = [a for a in s.rows if a.size]
        owned = {f.name: value.copy() for f in dataclasses.fields(obs)
                 if isinstance(value := getattr(obs, f.name), np.ndarray)
                 and any(np.may_share_memory(value, a) for a in held)}  # fmt: skip
        return dataclasses.replace(obs, **owned)

    def _period(self, rows, a_x, a_y) -> np.ndarray:
        """One period of ``rows`` (advanced in place) with the nominal proposals ``a_x``, ``a_y``: the behaviour
        codes ``(B,)``."""
        from ._fast_loop import step_kernel

        proposal = np.empty((len(a_x), 2))
        proposal[:, 0], proposal[:, 1] = a_x, a_y
        behaviour, finite = np.empty(len(a_x), np.int64), np.empty(len(a_x), np.bool_)
        step_kernel(self.prm_vec, self.period_prm, self.batch, rows, proposal, behaviour, finite,
                    sense_scratch(self.prm_vec, rows.x.shape[1]))
        self.check_finite(rows, finite)
        return behaviour

    def splice(self, rows: np.ndarray, part: Stepper, at: np.ndarray | None = None) -> None:
        """Rows ``rows`` of the batch become ``part``'s rows, in place: ``part`` steps ``len(rows)`` other scenarios
        (same settings and seed) and its kernel inputs replace those rows' (:func:`kernel_inputs` per row, so the
        rows' inputs are what a :class:`Stepper` over the spliced batch would hold: ``L0``'s profile, the world's key
        and the sensing bounds are the row's own, like the rest); the envs' resets, which would
        otherwise rebuild the whole batch's inputs for a few rows; ``at``: ``part``'s rows to take, in ``rows``'
        order (default: all of them, the vector env's resets take theirs from episodes prepared ahead,
        ``envs/reserve.py``). ``sim`` then describes the batch before the
        splice: :meth:`observe`, :meth:`step` and :meth:`finish`, which read it, refuse (the envs step with
        :meth:`step_with` and the kernels; :meth:`check_finite` reads the spliced scenario ids)."""
        for into, new in self.splice_pairs(part):
            into[rows] = new if at is None else new[at]

    def splice_pairs(self, part: Stepper) -> list[tuple[np.ndarray, np.ndarray]]:
        """What :meth:`splice` copies: ``(into, new)`` for each array of the batch's kernel inputs that has rows, row
        ``i`` of ``new`` (``part``'s) into row ``r`` of ``into`` (ours, in place: this batch counts as spliced from
        now on); the arrays whose batch axis is last (``BATCH_LAST``) transposed. ``part`` is checked as
        :meth:`splice` says."""
        same = (part.sim.seed == self.sim.seed and part.batch.x.shape[1] == self.batch.x.shape[1]
                and np.array_equal(part.prm_vec, self.prm_vec) and np.array_equal(part.period_prm, self.period_prm))
        if not same:
            raise ValueError("Stepper.splice: the part has other settings, another seed or another number of vehicle "
                             "slots than this batch")  # fmt: skip
        if any(getattr(b, name).shape[0] for name in BY_ID for b in (self.batch, part.batch)) or (
                part.batch.profile_t.shape[1] != self.batch.profile_t.shape[1]
                or part.batch.l0_profile_t.shape[1] != self.batch.l0_profile_t.shape[1]
                or part.batch.err_own.shape[1] != self.batch.err_own.shape[1]
                or part.batch.own_v_desired.shape[1] != self.batch.own_v_desired.shape[1]):  # fmt: skip
            raise ValueError("Stepper.splice: traffic hooks as data (WaveHooks, by scenario id), or L(N+1)'s or L0's "
                             "profiles, the own lane's sensing bounds or its slots of another length: such batches are "
                             "not spliced")  # fmt: skip
        if not self.spliced:  # (kernel_inputs may hand over the ClosedLoop's own arrays: from now on, ours)
            self.batch = type(self.batch)(*[a.copy() for a in self.batch])
        self.spliced = True
        return [(into.T, new.T) if name in BATCH_LAST else (into, new)
                for name, into, new in zip(self.batch._fields, self.batch, part.batch, strict=True)
                if name not in BATCH_SHARED and name not in BY_ID and name not in LOOP_ONLY]

    def _whole(self, what: str) -> None:
        if self.spliced:
            raise RuntimeError(f"Stepper.{what}: rows were spliced into this batch (splice), so its ClosedLoop no "
                               "longer describes them; build a Stepper over the batch as it is now")  # fmt: skip

    @staticmethod
    def rows_after(s: StepState):
        """A copy of ``s``'s rows for a kernel to advance in place (``s`` stays the state before the period)."""
        from ._fast_rows import Rows

        return Rows(*[a.copy() for a in s.rows])

    def check_finite(self, rows, finite: np.ndarray) -> None:
        """A :class:`FloatingPointError` naming the scenarios whose state a kernel found not finite."""
        if not finite.all():
            bad = np.flatnonzero(~finite)
            _non_finite(self.batch.scenario_id, bad, float(rows.rf[bad[0], 4]))


#: Settings the envs' compiled step (``envs/_fast.py``) does not take though :class:`Stepper` may run them for
#: ``simulate_batch``: none today. The realistic world runs there whole — the world's side (the own lane's ``L0``,
#: sensing error, the actuation delay) and the shield's (its sensing box, its delay where it is the world's: a shield's
#: delay other than the world's is refused by :func:`reasons`, as in the loop) — compared with the NumPy env bit for
#: bit, single env and vector env (``tests/test_env_realworld.py``). Setting → (the values the envs' compiled step
#: takes, the setting without which it changes nothing: ``None``, always).
ENV_WORLD: dict[str, tuple[tuple, str | None]] = {}


def steps_compiled(batch, cfg, traffic) -> list[str]:
    """Why :class:`Stepper` does not step this batch in the envs (empty: it does): :func:`reasons` without the batch
    size and the planner (the proposals are given), and :data:`ENV_WORLD`'s settings at other values."""
    out = reasons(batch, cfg, None, traffic, False, False, stepping=True)
    for name, (values, only_with) in ENV_WORLD.items():
        now = setting(cfg, name)
        if now not in values and (only_with is None or setting(cfg, only_with)):
            out.append(f"config.{name}={now!r} in the envs' compiled step (compiled: {values!r}; not compared with "
                       "the NumPy env)")  # fmt: skip
    return out
