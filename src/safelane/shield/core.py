"""The shield: a batched, stateful runtime supervisor over a pure functional core.

``init(situation, params, config, variant) -> ShieldState`` and
``step(state, situation, proposal, params, config, variant) -> (ShieldState, Decision)`` — the gymnax shape — and
:class:`Shield`, the stateful wrapper (``reset(situation)``, ``step(situation, proposal) -> Decision``). Every
period the shield

1. updates its belief about F (the aggressiveness assessment, :mod:`.assessment`) and checks what the others did
   against what its held plan assumed (the assumption monitor, :mod:`.monitor`);
2. takes L1's worst case and F's assumed type from the information its variant uses (:mod:`.policies`), or the
   most conservative ones after a breach;
3. checks the proposal (:mod:`.proposals`) and decides: proceed with it, hesitate, or abort on the held plan
   (:mod:`.decide`), or — once the lane change is complete — follow L1 responsibly.

:func:`step` is the list of those stages (:mod:`.stages`: observe → worst case → proposal → frame → decide →
command → remember); the configuration is :class:`~.config.ShieldConfig`.

It never sees a simulator's state: a :class:`~.situation.Situation` and a proposal in, a :class:`Decision` out
(ad-rss's shape), so the batched simulator, a Gymnasium environment, highway-env or SUMO all call it the same way.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..safety.evasion import plan_evasion
from ..safety.plan import EvasionPlan
from . import assessment as assess
from . import fast_step, rows, stages, validation, world
from .command import Command, InFlight
from .config import ShieldConfig
from .decision import Decision
from .monitor import Breach, Snapshot, observe_breaches
from .policies import ASSESSMENTS, variant_flags
from .proposals import proposal_arrays
from .realworld import carry_worst, delay_periods, in_flight_checked, own_plan, worst_corners
from .rules import rule_rows, rule_table
from .situation import Situation
from .stages import chain_analysis, exact, own_leader

__all__ = ["Shield", "ShieldConfig", "ShieldState", "chain_analysis", "init", "observe", "stages_step", "step"]


@dataclass(frozen=True)
class ShieldState:
    """Everything the shield carries from one period to the next (the batch on the leading axis)."""

    t: float
    plan: EvasionPlan  # the verified evasion plan held (time origin ``plan_t0``)
    plan_t0: np.ndarray
    plan_f_aggr: np.ndarray  # the F type the held plan assumed
    belief: assess.AssessmentState
    breach: Breach
    completed: np.ndarray
    last: Snapshot | None  # the previous period, for the monitor
    pending: InFlight | None = None  # the commands in flight (actuation delay), oldest first


def init(situation: Situation, params: Params, config: ShieldConfig | None = None, variant="CV_all") -> ShieldState:
    """The shield's state for a lane change starting at ``situation``: the plan held at the start is computed under
    the most conservative assumptions (L1 at the others' maximum ``a_o_d``, F aggressive); the world model's other
    vehicles (``situation.others``) folded into F, the chain and the own lane first, as every period folds them."""
    cfg = config or ShieldConfig()
    if situation.others is not None:
        situation = world.roles(situation, params)
    n = len(situation)
    delay = delay_periods(cfg, params) * params.dt
    pending = InFlight.idle(n, delay_periods(cfg, params)) if delay > 0.0 else None
    s = situation if cfg.sensing else exact(situation)
    s = worst_corners(s)[0]
    ex, ey, evx, evy = s.ego_x, s.ego_y, s.ego_vx, s.ego_vy
    l1x, l1v, fx, fv = s.chain_x[:, 0], s.chain_v[:, 0], s.f_x, s.f_v
    if pending is not None:  # the plan starts once the commands in flight have acted
        ex, ey, evx, evy = pending.carry(ex, ey, evx, evy, params.dt)
        l1x, l1v = carry_worst(l1x, l1v, params.others_decel, delay)
        fx, fv = carry_worst(fx, fv, -params.a_x_a, delay)
    own = own_now = own_leader(s, cfg, params, np.zeros(n, bool), np.ones(n, bool))
    if own is not None and pending is not None:
        own = (*carry_worst(own[0], own[1], own[2], delay), own[2])
    # The plan held at the start: one candidate check of "cruise laterally as now" would also verify the period;
    # the plan alone is what init needs (the first step verifies every proposal).
    plan = plan_evasion(ex, ey, evx, evy, l1x, l1v, params.others_decel, fx, fv, True, params)
    if own is not None and np.isfinite(own[0]).any():
        plan = own_plan(plan, (ex, ey, evx, evy, l1x, l1v, np.full(n, params.others_decel), fx, fv, np.ones(n, bool)),
                         own, params)  # fmt: skip
    if pending is not None:  # nothing verified the commands acting at the start: check their window now
        plan = in_flight_checked(plan, s, own_now, delay, params)
    return ShieldState(
        t=situation.t,
        plan=plan,
        plan_t0=np.full(n, situation.t + delay),
        plan_f_aggr=np.ones(n, bool),
        belief=ASSESSMENTS[cfg.assessment].start(n, cfg),
        breach=Breach.none(n),
        completed=np.zeros(n, bool),
        last=None,
        pending=pending,
    )


def step(
    state: ShieldState,
    situation: Situation,
    proposal,
    params: Params,
    config: ShieldConfig | None = None,
    variant="CV_all",
    *,
    planner_name: str = "the nominal planner",
    chain=None,
) -> tuple[ShieldState, Decision]:
    """One period: ``(state, situation, proposal) -> (state', Decision)``.

    The compiled period (:mod:`.fast_step`, one call for every row) where it implements the configuration, the
    variant and what the situation and state carry; else :func:`stages_step`, the stages of :mod:`.stages` in order.
    Both give the same bits (``tests/test_fast_period.py``). ``proposal``: ``(a_x, a_y)`` arrays of shape ``(B,)``
    in the shield's frame. ``variant``: a registered variant name, or ``(B,)`` names or registry indices. ``chain``:
    the :func:`chain_analysis` of this very situation, when the caller has it already (the simulator computes it
    for the traffic): taken as given on both paths.
    """
    cfg = config or ShieldConfig()
    n = len(situation)
    if fast_step.kernel() is not None and not fast_step.refusals(cfg, variant, n):
        folded_state, folded, folded_chain = fold_world(state, situation, params, cfg, chain)
        if not fast_step.situation_refusals(folded, cfg, folded_state):
            arrays = proposal_arrays(planner_name, proposal, n)
            packed, decision = fast_step.step(fast_step.Packed.of(folded_state), folded, arrays, params, cfg,
                                              np.column_stack(variant_flags(variant, n)), folded_chain,
                                              rule_table(rule_rows(variant, n), n, params))  # fmt: skip
            return packed.state(params, decision), decision
    return stages_step(state, situation, proposal, params, cfg, variant, planner_name=planner_name, chain=chain)


def fold_world(state: ShieldState, situation: Situation, params: Params, config: ShieldConfig, chain=None):
    """``(state, situation, chain)`` with the world model's other vehicles folded into F, the chain and the own lane
    (:func:`.world.fold`, what :func:`.stages.observe` does first) and the situation's ``others`` then dropped, so
    the compiled period (which reads the roles, not the others) can take it; unchanged without ``others``."""
    if situation.others is None:
        return state, situation, chain
    state, situation, chain = world.fold(state, situation, params, config, chain)
    return state, dataclasses.replace(situation, others=None), chain


def stages_step(
    state: ShieldState,
    situation: Situation,
    proposal,
    params: Params,
    config: ShieldConfig | None = None,
    variant="CV_all",
    *,
    planner_name: str = "the nominal planner",
    chain=None,
) -> tuple[ShieldState, Decision]:
    """One period through the stages of :mod:`.stages` in order, on NumPy arrays (the compiled parts they call
    aside): the reference of the compiled period, and the path of every setting it does not implement. Arguments as
    :func:`step`'s."""
    cfg = config or ShieldConfig()
    n = len(situation)
    flags = variant_flags(variant, n)
    ruled = rule_rows(variant, n)  # rows another registered decision rule decides (RSS); [] for the paper's
    paper_rule = np.ones(n, bool)
    for _, rule_idx in ruled:
        paper_rule[rule_idx] = False

    obs = stages.observe(state, situation, params, cfg, chain)
    worst = stages.worst_case(obs, flags, params, cfg)
    prop = stages.proposal(proposal, n, params, planner_name)
    fr = stages.frame(state, obs, worst, params, cfg)
    verdicts = stages.decide(state, obs, worst, prop, fr, paper_rule, ruled, flags, params, cfg)
    cmd = stages.command(state, obs, worst, prop, fr, verdicts, paper_rule, params)
    plan, plan_t0, plan_f_aggr, snapshot, breach = stages.remember(state, obs, worst, fr, verdicts, params)

    active = ~state.completed
    pending = state.pending
    done = verdicts.completing & active
    new_state = ShieldState(
        t=obs.situation.t + params.dt, plan=plan, plan_t0=plan_t0, plan_f_aggr=plan_f_aggr, belief=obs.belief,
        breach=breach, completed=state.completed | verdicts.completing, last=snapshot,
        pending=None if pending is None else pending.push(Command.issued(cmd.a_x, cmd.a_y, cmd.abort, done))[1],
    )  # fmt: skip
    decision = Decision(
        behaviour=verdicts.behaviour, a_x=cmd.a_x, a_y=cmd.a_y, completing=done,
        invalid=prop.invalid & active, _plan=plan, plan_t0=plan_t0, l1_decel=worst.l1_decel, f_aggressive=worst.f_aggr,
        breach=breach, nominal_x=prop.nominal_x, nominal_y=prop.nominal_y, _abort=cmd.abort,
    )  # fmt: skip
    return new_state, decision


def observe(
    state: ShieldState, situation: Situation, params: Params, config: ShieldConfig | None = None
) -> ShieldState:
    """The state with the monitor's view of the last period recorded, without deciding anything (e.g. after a run's
    final period, which :func:`step` would observe only at the next one): :func:`.stages.observe`'s comparison, at
    the sensing box's observed corner where ``config.sensing`` is on (the default) and on the measurements as exact
    where it is off (as the next period's :func:`step` would compare them)."""
    if state.last is None:
        return state
    if situation.others is not None:  # the roles the last period's snapshot holds (world.py)
        situation = world.roles(situation, params)
    if config is not None and not config.sensing:  # the shield takes the measurements as exact (stages.observe)
        situation = exact(situation)
    breach = observe_breaches(state.breach, state.last, worst_corners(situation)[1], params, situation.t)
    return dataclasses.replace(state, breach=breach)


class Shield:
    """The stateful shield for a batch of ``B`` lane changes: ``reset(situation)``, then ``step(situation,
    proposal) -> Decision`` every control period (``params.dt``).

    Example::

        shield = Shield(Params(), variant="CV_all")          # or Shield.from_preset("paper", variant="CV_all")
        shield.reset(situation)
        decision = shield.step(situation, (a_x, a_y))   # apply decision.a_x, decision.a_y for one period

    ``params``: a :class:`~safelane.Params` or a mapping of its fields (default ``Params()``); ``config``: a
    :class:`ShieldConfig` or a mapping of its fields. Bad arguments raise :class:`~safelane.errors.InputError` here,
    naming the argument (:mod:`.validation`). ``a_x``/``a_y`` are ``(B,)`` arrays, or plain numbers for all rows.
    """

    def __init__(self, params: Params | None = None, variant="CV_all", config: ShieldConfig | None = None):
        self.params = validation.shield_params(params)
        self.config = validation.shield_config(config)
        self.variant = validation.shield_variant(variant)
        self._state: ShieldState | None = None
        self._packed: fast_step.Packed | None = None  # the state as the compiled period keeps it (fast_step)
        self._refused: dict[int, list[str]] = {}  # fast_step.refusals per batch size
        self._flag_rows: dict[int, np.ndarray] = {}
        #: Which path ran the last period: ``"compiled"`` (:mod:`.fast_step`) or ``"stages"`` (:func:`step`).
        self.last_path: str | None = None

    @property
    def state(self) -> ShieldState | None:
        """The :class:`ShieldState` after the last period (unpacked from the compiled path's arrays when read)."""
        if self._state is None and self._packed is not None:
            self._state = self._packed.state(self.params)
        return self._state

    @property
    def rows(self) -> int:
        """The batch size of the state held (0 before ``reset``), read without unpacking it."""
        if self._packed is not None:
            return len(self._packed.count)
        return 0 if self._state is None else len(self._state.completed)

    @property
    def completed(self) -> np.ndarray | None:
        """``(B,)`` whether each row's lane change has completed (``None`` before ``reset``), read without unpacking
        the compiled path's arrays."""
        if self._packed is not None:
            return self._packed.sk[:, 3].copy()
        return None if self._state is None else np.asarray(self._state.completed, bool).copy()

    def regroup(self, keep, situation: Situation | None = None, t: float | None = None) -> None:
        """A batch whose vehicles come and go: hold the rows ``keep`` of the state (in that order), then new rows
        started at ``situation`` (:func:`init`, with a neutral monitor snapshot where the kept rows have one:
        :func:`.rows.neutral_snapshot`); ``t``: the state's time from now (default: unchanged). The compiled
        path's state stays packed. No rows at all: nothing held (``reset`` or ``regroup`` with a situation next)."""
        keep = np.asarray(keep, np.int64)
        fresh = None if situation is None or not len(situation) else init(situation, self.params, self.config,
                                                                           self.variant)  # fmt: skip
        held = self.rows > 0 and len(keep) > 0  # (then the state is packed, or unpacked in _state)
        if not held and fresh is None:
            self.state = None
            return
        same = held and len(keep) == self.rows and (keep == np.arange(len(keep))).all()
        if fresh is not None and held:
            last = self._packed.snapshot if self._packed is not None else self._state.last
            if last is not None:
                fresh = dataclasses.replace(fresh, last=rows.neutral_snapshot(len(fresh.completed),
                                                                              situation.chain_x.shape[1],
                                                                              self.params))  # fmt: skip
        if held and self._packed is not None:
            out = self._packed if same else self._packed.take(keep)
            out = out if fresh is None else out.join(fast_step.Packed.of(fresh))
            self._packed, self._state = dataclasses.replace(out, t=out.t if t is None else float(t)), None
            return
        state = None if not held else self._state if same else rows.take_rows(self._state, keep)
        state = fresh if state is None else state if fresh is None else rows.join_rows(state, fresh)
        self.state = dataclasses.replace(state, t=state.t if t is None else float(t))

    def _flags(self, n: int):
        """The variant's ``(B, 3)`` flags and the rows' decision rules (:func:`.rules.rule_table`) for ``n`` rows
        (cached: the variant is fixed)."""
        if n not in self._flag_rows:
            table = rule_table(rule_rows(self.variant, n), n, self.params)
            self._flag_rows[n] = (np.column_stack(variant_flags(self.variant, n)), table)
        return self._flag_rows[n]

    @state.setter
    def state(self, value: ShieldState | None) -> None:
        self._state, self._packed = value, None

    def refusals(self, situation: Situation) -> list[str]:
        """Why this period would not run compiled (empty: it would; :mod:`.fast_step`)."""
        n = len(situation)
        if n not in self._refused:  # (the kernel's presence is read once per batch size, as the refusals)
            self._refused[n] = fast_step.refusals(self.config, self.variant, n)
            if fast_step.kernel() is None:
                self._refused[n] = ["numba missing or SAFELANE_NO_NUMBA=1"]
        held = None if self._packed is not None else self._state
        return self._refused[n] + fast_step.situation_refusals(situation, self.config, held)

    @classmethod
    def from_preset(cls, preset="paper", variant="CV_all", config=None) -> Shield:
        """The shield a preset's experiments run (``safelane.load_preset``): its ``params`` and the shield settings
        of its ``sim`` section (assessment, completion rule, monitor, ...); ``config`` overrides some of them."""
        params, cfg = validation.preset_parts(preset, config)
        return cls(params, variant=variant, config=cfg)

    def reset(self, situation: Situation) -> None:
        validation.situation_arg(situation, "Shield.reset").validate(self.params)
        self.state = init(situation, self.params, self.config, self.variant)

    def step(self, situation: Situation, proposal) -> Decision:
        if self._state is None and self._packed is None:
            raise RuntimeError("Shield.step before Shield.reset(situation): the shield needs the starting situation")
        validation.situation_arg(situation, "Shield.step").validate(self.params)
        rows = self.rows
        if len(situation) != rows:
            raise ValueError(f"the situation has {len(situation)} rows; the shield was reset with {rows}")
        proposal = validation.batch_proposal(proposal, len(situation))
        if situation.others is not None and not self.refusals(dataclasses.replace(situation, others=None)):
            # the world model folded here (as the stages' observe would), so the period can run compiled
            self.state, situation, _ = fold_world(self.state, situation, self.params, self.config)
        if not self.refusals(situation):
            packed = self._packed if self._packed is not None else fast_step.Packed.of(self._state)
            proposal = proposal_arrays("the nominal planner", proposal, len(situation))
            flags, rules = self._flags(len(situation))
            self._packed, decision = fast_step.step(packed, situation, proposal, self.params, self.config, flags,
                                                    rule=rules)  # fmt: skip
            self._state, self.last_path = None, "compiled"
            return decision
        self.state, decision = stages_step(self.state, situation, proposal, self.params, self.config, self.variant)
        self.last_path = "stages"
        return decision
