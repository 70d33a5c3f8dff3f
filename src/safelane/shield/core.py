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

It never sees a simulator's state: a :class:`~.situation.Situation` and a proposal in, a :class:`Decision` out
(ad-rss's shape), so the batched simulator, a Gymnasium environment, highway-env or SUMO all call it the same way.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from ..params import Params
from ..safety._backend import ARRAY
from ..safety.chain import propagate_chain
from ..safety.evasion import plan_evasion
from ..safety.plan import EvasionPlan, set_rows
from ..safety.responsible import responsible_accel, responsible_bound
from . import assessment as assess
from .decide import ABORT, COMPLETED, HESITATE, PROCEED, check_candidate, hesitate_lateral, plan_motion
from .decision import Decision
from .monitor import Breach, Snapshot, observe_breaches
from .policies import ASSESSMENTS, COMPLETION_RULES, check_policy, variant_flags
from .proposals import check_proposal
from .realworld import (
    Pending,
    carry_worst,
    chain_bounds,
    delay_periods,
    in_flight_checked,
    issued_piece,
    own_lane_decel,
    own_plan,
    worst_corners,
)
from .rules import RuleInputs, rule_rows
from .situation import Situation


class ShieldConfig(BaseModel):
    """How the shield decides (not what it knows: that is the :class:`Situation`)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    assessment: str = Field("observed", description="Registered assessment model ('observed', 'truth').")
    assess_window: int = Field(5, ge=2, description="Observations in the assessment's slope window.")
    assess_threshold: float = Field(0.2, gt=0.0, description="Evidence threshold on F's acceleration [m/s²].")
    monitor: bool = Field(True, description="After a breach of the assumptions, assume the worst (L1 at a_x_d, F "
                          "aggressive); False only records breaches.")  # fmt: skip
    completion: str = Field("commit_guard", description="Registered completion rule.")
    assess_delay_s: float = Field(1.5, ge=0.0, description="'slow' assessment: mean extra delay of a verdict [s].")
    assess_miss: float = Field(0.0, ge=0.0, le=1.0, description="'slow' assessment: P(a collaborative F is missed).")
    enabled: bool = Field(True, description="False passes the (clipped, checked) proposal through unfiltered.")
    actuation_delay_s: float = Field(0.0, ge=0.0, le=1.0, description="Actuation delay δ [s]: a command acts δ after "
                                     "it is issued, the ones issued before keep acting meanwhile; a whole number of "
                                     "control periods (0 = the paper).")  # fmt: skip
    own_lane: bool = Field(True, description="Keep p_m to the own-lane leaders (L0) the situation carries; False "
                           "ignores them (the paper's shield, which assumes an empty original lane).")  # fmt: skip
    sensing: bool = Field(True, description="Take the worst case over the situation's sensing-error bounds; False "
                          "takes the measurements as exact (the paper's shield).")  # fmt: skip

    @field_validator("assessment")
    @classmethod
    def _assessment(cls, value: str) -> str:
        return check_policy("assessment", value, ASSESSMENTS)

    @field_validator("completion")
    @classmethod
    def _completion(cls, value: str) -> str:
        return check_policy("completion rule", value, COMPLETION_RULES)


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
    pending: Pending | None = None  # the commands in flight (actuation delay), oldest first


def chain_analysis(situation: Situation, prm: Params):
    """``(bounds (B, M), unsafe (B,))``: each chain vehicle's worst-case deceleration (Eqs. 1–3, corrected) from
    what the ego knows."""
    n = len(situation)
    m = situation.chain_x.shape[1]
    if situation.err_chain is not None:  # each link at its own worst corner (sensing error)
        s = situation
        return chain_bounds(s.chain_x, s.chain_v, s.chain_promise, s.n_connected, s.chain_human, s.err_chain, prm)
    in_chain = np.arange(m - 1)[None, :] < situation.n_connected[:, None]
    promise = np.where(in_chain, situation.chain_promise, prm.a_x_d)
    margin = np.where(situation.chain_human & in_chain, prm.p_m_human, prm.p_m)
    with np.errstate(all="ignore"):  # the situation was validated where it was built: the scan alone
        decel, _, unsafe = propagate_chain(
            ARRAY, situation.chain_x.T, situation.chain_v.T, promise.T, margin.T, prm, m - 1
        )
    bounds = np.column_stack([np.broadcast_to(d, (n,)) for d in decel])
    return bounds, np.broadcast_to(np.asarray(unsafe, bool), (n,))


def init(situation: Situation, params: Params, config: ShieldConfig | None = None, variant="CV_all") -> ShieldState:
    """The shield's state for a lane change starting at ``situation``: the plan held at the start is computed under
    the most conservative assumptions (L1 at ``a_x_d``, F aggressive)."""
    cfg = config or ShieldConfig()
    n = len(situation)
    delay = delay_periods(cfg, params) * params.dt
    pending = Pending.idle(n, delay_periods(cfg, params), params.dt) if delay > 0.0 else None
    s = situation if cfg.sensing else _exact(situation)
    s = worst_corners(s)[0]
    ex, ey, evx, evy = s.ego_x, s.ego_y, s.ego_vx, s.ego_vy
    l1x, l1v, fx, fv = s.chain_x[:, 0], s.chain_v[:, 0], s.f_x, s.f_v
    if pending is not None:  # the plan starts once the commands in flight have acted
        ex, ey, evx, evy = pending.carry(ex, ey, evx, evy)
        l1x, l1v = carry_worst(l1x, l1v, params.a_x_d, delay)
        fx, fv = carry_worst(fx, fv, -params.a_x_a, delay)
    own = own_now = _own(s, cfg, params, np.zeros(n, bool), np.ones(n, bool))
    if own is not None and pending is not None:
        own = (*carry_worst(own[0], own[1], own[2], delay), own[2])
    # The plan held at the start: one candidate check of "cruise laterally as now" would also verify the period;
    # the plan alone is what init needs (the first step verifies every proposal).
    plan = plan_evasion(ex, ey, evx, evy, l1x, l1v, params.a_x_d, fx, fv, True, params)
    if own is not None and np.isfinite(own[0]).any():
        plan = own_plan(plan, (ex, ey, evx, evy, l1x, l1v, np.full(n, params.a_x_d), fx, fv, np.ones(n, bool)),
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


def _exact(s: Situation) -> Situation:
    return dataclasses.replace(s, err_f=None, err_chain=None, err_own=None)


def _own(s: Situation, cfg: ShieldConfig, prm: Params, informed, broken):
    """``(l0_x, l0_v, l0_decel)`` for the check, or ``None`` (no own-lane leader, or the paper's shield)."""
    if not cfg.own_lane or not s.has_own_lane:
        return None
    return s.own_x[:, 0], s.own_v[:, 0], own_lane_decel(s, prm, informed, broken)


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
    """One period: ``(state, situation, proposal) -> (state', Decision)`` (see the module docstring).

    ``proposal``: ``(a_x, a_y)`` arrays of shape ``(B,)`` in the shield's frame. ``variant``: a registered variant
    name, or ``(B,)`` names or registry indices. ``chain``: the :func:`chain_analysis` of this very situation, when
    the caller has it already (the simulator computes it for the traffic).
    """
    cfg = config or ShieldConfig()
    prm = params
    s = situation
    dt = prm.dt
    n = len(s)
    uses_chain, uses_f_v2x, uses_assessment = variant_flags(variant, n)
    ruled = rule_rows(variant, n)  # rows another registered decision rule decides (RSS); [] for the paper's
    paper_rule = np.ones(n, bool)
    for _, rule_idx in ruled:
        paper_rule[rule_idx] = False

    # 1. What happened last period: the assessment's new observation, the monitor's comparison.
    assessment = ASSESSMENTS[cfg.assessment]
    belief = assessment.update(state.belief, s, dt, cfg)
    if not cfg.sensing:
        s = _exact(s)
    s_eval, s_obs = worst_corners(s)  # the analysis' corners of the sensing-error box, and the monitor's
    bounds, unsafe = chain_analysis(s, prm) if chain is None else chain
    breach = state.breach
    if state.last is not None:
        breach = observe_breaches(state.breach, state.last, s_obs, prm, s.t)

    # 2. The worst case from the information the variant uses; the most conservative one after a breach.
    l1_decel = np.where(uses_chain & ~unsafe, bounds[:, 0], prm.a_x_d)
    assessed = assessment.aggressive(belief, s)
    trusted = uses_f_v2x & s.f_connected & s.f_collaborative
    f_aggr = np.where(trusted, False, np.where(uses_assessment, assessed, True))
    broken = breach.any if cfg.monitor else np.zeros(n, bool)
    if cfg.monitor:
        l1_decel = np.where(broken, prm.a_x_d, l1_decel)
        f_aggr = f_aggr | broken
    own = _own(s, cfg, prm, uses_chain, broken)
    if own is not None:
        own = (s_eval.own_x[:, 0], s_eval.own_v[:, 0], own[2])

    # 3. The proposal, checked; then proceed / hesitate / abort where the lane change is under way.
    a_x, a_y, invalid = check_proposal(planner_name, proposal, n, prm)
    nominal_x, nominal_y = a_x, a_y
    a_x = np.clip(a_x, -prm.a_x_d, prm.a_x_a)
    a_y = np.clip(a_y, -prm.a_y_m, prm.a_y_m)
    ex, ey, evx, evy = s.ego_x, s.ego_y, s.ego_vx, s.ego_vy
    l1x, l1v, fx, fv = s_eval.chain_x[:, 0], s_eval.chain_v[:, 0], s_eval.f_x, s_eval.f_v
    snap_f = (fx, fv, ex)
    delay = delay_periods(cfg, prm) * dt
    if delay > 0.0:  # decide for the period that starts once the commands in flight have acted (realworld.py)
        ex, ey, evx, evy = state.pending.carry(ex, ey, evx, evy)
        l1x, l1v = carry_worst(l1x, l1v, l1_decel, delay)
        fx, fv = carry_worst(fx, fv, np.where(f_aggr, -prm.a_x_a, prm.a_x_d), delay)
        if own is not None:
            own = (*carry_worst(own[0], own[1], own[2], delay), own[2])
    active = ~state.completed
    behaviour = np.where(active, PROCEED, COMPLETED)
    completing = np.zeros(n, bool)
    accepted = []
    a_yh = hesitate_lateral(evy, prm)
    if cfg.enabled:
        rows = np.flatnonzero(active & paper_rule)
        skip = rows[:0]
        for code, lateral in ((PROCEED, a_y), (HESITATE, a_yh)):
            if code == PROCEED:  # an invalid proposal is never executed: those rows start at hesitate
                skip, rows = rows[invalid[rows]], rows[~invalid[rows]]
            elif skip.size:
                rows = np.sort(np.concatenate([rows, skip]))
            if rows.size == 0:
                continue
            verdict = check_candidate(
                *(arr[rows] for arr in (ex, ey, evx, evy, a_x, lateral, l1x, l1v, l1_decel, fx, fv, f_aggr)), prm,
                completion=COMPLETION_RULES[cfg.completion], own=None if own is None else tuple(a[rows] for a in own),
            )  # fmt: skip
            ok_rows = rows[verdict.ok]
            behaviour[ok_rows] = code
            completing[ok_rows] = verdict.completing[verdict.ok]
            accepted.extend((rows[idx], plan) for idx, plan in verdict.plans)
            rows = rows[~verdict.ok]
        behaviour[rows] = ABORT
    else:
        completing = active & (ey + evy * dt + 0.5 * a_y * dt * dt >= prm.y_boundary)

    # After completion: centre in the target lane, follow L1 responsibly under its worst case.
    done = np.flatnonzero(state.completed & paper_rule)
    ax_cmd = a_x.copy()
    ay_cmd = np.where(behaviour == HESITATE, a_yh, a_y)
    if done.size:
        ax_cmd[done] = responsible_accel(
            a_x[done], (l1x - ex - prm.p_m)[done], evx[done], l1v[done], l1_decel[done], prm
        )
        ay_cmd[done] = np.clip(0.8 * (prm.lane_width - ey[done]) - 1.6 * evy[done], -prm.a_y_m, prm.a_y_m)
    abort_rows = np.flatnonzero(behaviour == ABORT)
    abort = (abort_rows, None, None, None, None, None)
    if abort_rows.size:  # only the aborting rows follow their plan: evaluate it there alone
        age = np.maximum(s.t + delay - state.plan_t0[abort_rows], 0.0)  # (round-off of the summed periods)
        knots, px, vx, py, vy = plan_motion(state.plan.take(abort_rows), age, dt)
        abort = (abort_rows, knots, px, vx, py, vy)
        # The accelerations at the period's start: the first segment of positive length (switches already past
        # leave zero-length segments at the front; the knots span the period, so one segment has length dt > 0).
        first = np.argmax(np.diff(knots, axis=1) > 0.0, axis=1)
        r = np.arange(abort_rows.size)
        span = knots[r, first + 1] - knots[r, first]
        ax_cmd[abort_rows] = (vx[r, first + 1] - vx[r, first]) / span
        ay_cmd[abort_rows] = (vy[r, first + 1] - vy[r, first]) / span
    if cfg.enabled:  # the rows of another rule: its decision (an RSS response is an abort without a held plan)
        for rule, idx in ruled:
            fields = (ex, ey, evx, evy, s.chain_x, s.chain_v, fx, fv, a_x, a_y, a_yh, invalid, l1_decel,
                      uses_chain & ~unsafe, state.completed, bounds, s.n_connected)  # fmt: skip
            inputs = RuleInputs(*(arr[idx] for arr in fields))
            behaviour[idx], ax_cmd[idx], ay_cmd[idx], completing[idx] = rule.decide(inputs, prm)

    new_plan = set_rows(state.plan, accepted)
    replanned = (behaviour == PROCEED) | (behaviour == HESITATE)
    plan_f_aggr = state.plan_f_aggr.copy()
    for rows_acc, _ in accepted:
        plan_f_aggr[rows_acc] = f_aggr[rows_acc]
    # For the monitor at the next period: what a responsible follower of the ego could do this period.
    f_limit = np.full(n, np.inf)  # only an F the held plan takes for collaborative, with the ego ahead, is watched
    sfx, sfv, sex = snap_f  # the monitor compares states at the period's start, not carried over the delay
    watch = np.flatnonzero(active & ~plan_f_aggr & (sex - sfx > 0.0))
    if watch.size:
        with np.errstate(all="ignore"):
            gap = (sex - sfx - prm.p_m)[watch]
            limit = responsible_bound(gap, sfv[watch], s.ego_vx[watch], np.full(watch.size, prm.a_x_d), prm)
        f_limit[watch] = np.maximum(limit, -prm.a_x_d)
    last = Snapshot(
        chain_x=s_eval.chain_x, chain_v=s_eval.chain_v, bounds=bounds, n_connected=s.n_connected, f_x=sfx, f_v=sfv,
        f_limit=f_limit, plan_l1_decel=new_plan.l1_decel,
        plan_f_aggr=plan_f_aggr, active=active,
    )  # fmt: skip
    if s.v2x_stale is not None:
        breach = _with_stale(breach, active & s.v2x_stale, s.t)
    new_state = ShieldState(
        t=s.t + dt,
        plan=new_plan,
        plan_t0=np.where(replanned, s.t + delay + dt, state.plan_t0),
        plan_f_aggr=plan_f_aggr,
        belief=belief,
        breach=breach,
        completed=state.completed | completing,
        last=last,
        pending=None if state.pending is None else state.pending.push(issued_piece(ax_cmd, ay_cmd, abort, dt)),
    )
    decision = Decision(
        behaviour=behaviour, a_x=ax_cmd, a_y=ay_cmd, completing=completing & active, invalid=invalid & active,
        plan=new_plan, plan_t0=new_state.plan_t0, l1_decel=l1_decel, f_aggressive=f_aggr, breach=breach,
        nominal_x=nominal_x, nominal_y=nominal_y, _abort=abort,
    )  # fmt: skip
    return new_state, decision


def observe(state: ShieldState, situation: Situation, params: Params) -> ShieldState:
    """The state with the monitor's view of the last period recorded, without deciding anything (e.g. after a run's
    final period, which :func:`step` would observe only at the next one)."""
    if state.last is None:
        return state
    breach = observe_breaches(state.breach, state.last, worst_corners(situation)[1], params, situation.t)
    return dataclasses.replace(state, breach=breach)


def _with_stale(breach: Breach, stale, t: float) -> Breach:
    from .monitor import BREACH_KINDS

    col = BREACH_KINDS.index("stale_v2x")
    new = stale & ~breach.flags[:, col]
    if not new.any():
        return breach
    flags = breach.flags.copy()
    flags[:, col] |= stale
    first = np.where(np.isnan(breach.first_s) & new, t, breach.first_s)
    return Breach(flags=flags, first_s=first)


class Shield:
    """The stateful shield for a batch of ``B`` lane changes: ``reset(situation)``, then ``step(situation,
    proposal) -> Decision`` every control period (``params.dt``).

    Example::

        shield = Shield(Params(), variant="CV_all")
        shield.reset(situation)
        decision = shield.step(situation, (a_x, a_y))   # apply decision.a_x, decision.a_y for one period
    """

    def __init__(self, params: Params | None = None, variant="CV_all", config: ShieldConfig | None = None):
        self.params = params or Params()
        self.config = config or ShieldConfig()
        variant_flags(variant, 1 if isinstance(variant, str) else len(np.atleast_1d(variant)))  # validate now
        self.variant = variant
        self.state: ShieldState | None = None

    def reset(self, situation: Situation) -> None:
        situation.validate(self.params)
        self.state = init(situation, self.params, self.config, self.variant)

    def step(self, situation: Situation, proposal) -> Decision:
        if self.state is None:
            raise RuntimeError("Shield.step before Shield.reset(situation): the shield needs the starting situation")
        situation.validate(self.params)
        if len(situation) != len(self.state.completed):
            raise ValueError(f"the situation has {len(situation)} rows; the shield was reset with "
                             f"{len(self.state.completed)}")  # fmt: skip
        self.state, decision = step(self.state, situation, proposal, self.params, self.config, self.variant)
        return decision
