"""The stages of one control period of the shield, in the order :func:`safelane.shield.core.step` calls them
(ad-rss's pipeline shape):

1. :func:`observe` — the aggressiveness assessment's new observation, the sensing-error corners, the chain analysis
   (Eqs. 1–3) and the assumption monitor's comparison of the last period;
2. :func:`worst_case` — L1's worst-case deceleration and F's assumed type from the information the variant uses,
   the most conservative ones after a breach; the own-lane leader's;
3. :func:`proposal` — the nominal planner's proposal checked and clipped to the limits;
4. :func:`frame` — the states the decision is made from: the period's start, or — with an actuation delay — the
   moment the commands in flight have acted;
5. :func:`decide` — proceed / hesitate / abort for the rows under the paper's rule, by the candidate check of
   Eq. 9; the rows of another registered rule (RSS) by that rule;
6. :func:`command` — the accelerations to apply: the accepted proposal, hesitation, responsible following after
   completion, or the held plan's exact motion when aborting;
7. :func:`remember` — the state carried to the next period: the plans accepted, the monitor's snapshot (and what a
   responsible F may do), the commands in flight.

Each stage is a function of named records (:class:`Observed`, :class:`WorstCase`, :class:`Proposal`,
:class:`Frame`, :class:`Verdicts`, :class:`Commands`), every array with the batch ``(B,)`` on its leading axis.
The real-world extensions enter as stages' inputs, not threads through them: the sensing-error box in
:func:`observe` (the corners), the own-lane leader in :func:`worst_case`, the actuation delay in :func:`frame`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, FEASIBILITY_TOL_M, jitable
from ..safety.chain import propagate_chain
from ..safety.plan import set_rows
from ..safety.responsible import responsible_accel, responsible_bound, responsible_ok
from .assessment import AssessmentState
from .config import ShieldConfig
from .decide import ABORT, COMPLETED, HESITATE, PROCEED, check_candidate, hesitate_lateral, plan_motion
from .monitor import BREACH_KINDS, Anchor, Breach, Snapshot, observe_breaches
from .policies import ASSESSMENTS, COMPLETION_RULES
from .proposals import check_proposal
from .realworld import carried_others, carry_worst, chain_bounds, delay_periods, own_lane_decel, worst_corners
from .rules import RuleInputs
from .situation import Situation
from .world import fold as fold_others


@dataclass(frozen=True)
class Observed:
    """Stage 1's output: what the ego knows this period, and what it learnt about the last one."""

    situation: Situation  # the situation as the analysis takes it (measurements exact where the config says so)
    evaluated: Situation  # the analysis' corners of the sensing-error box (the monitor's are used here alone)
    belief: AssessmentState  # the assessment's belief about F after this period's observation
    bounds: np.ndarray  # (B, M) each chain vehicle's worst-case deceleration (Eqs. 1–3)
    unsafe: np.ndarray  # (B,) the chain scan found a link that cannot keep its margin
    breach: Breach  # the monitor's record, with the last period compared


@dataclass(frozen=True)
class WorstCase:
    """Stage 2's output: the worst case the decision assumes."""

    l1_decel: np.ndarray  # (B,) L1's worst-case deceleration [m/s²]
    f_aggr: np.ndarray  # (B,) F taken for aggressive (after a breach too, where the monitor acts on it)
    own: tuple | None  # (l0_x, l0_v, l0_decel) at the analysis' corner, or None (no own-lane leader checked)


@dataclass(frozen=True)
class Proposal:
    """Stage 3's output: the nominal planner's proposal, checked and clipped."""

    a_x: np.ndarray  # (B,) clipped to [-a_x_d, a_x_a]
    a_y: np.ndarray  # (B,) clipped to [-a_y_m, a_y_m]
    invalid: np.ndarray  # (B,) the proposal failed its check (never executed)
    nominal_x: np.ndarray  # (B,) as proposed (after the check's substitution of failed proposals)
    nominal_y: np.ndarray


@dataclass(frozen=True)
class Frame:
    """Stage 4's output: the states the decision is made from (the worst case carried over the delay)."""

    ego: tuple  # (x, y, vx, vy)
    l1: tuple  # (x, v)
    f: tuple  # (x, v)
    own: tuple | None  # (l0_x, l0_v, l0_decel) or None
    delay_s: float  # the actuation delay [s] (0: the paper's)


@dataclass(frozen=True)
class Verdicts:
    """Stage 5's output: each row's behaviour and the plans it verified."""

    behaviour: np.ndarray  # (B,) PROCEED / HESITATE / ABORT / COMPLETED
    completing: np.ndarray  # (B,) this period crosses into the target lane for good
    accepted: list  # [(rows, EvasionPlan)] the plans verified this period
    a_yh: np.ndarray  # (B,) the hesitation's lateral acceleration
    ruled: list  # [(rows, a_x, a_y)] the commands of another rule's rows (RSS)


@dataclass(frozen=True)
class Commands:
    """Stage 6's output: what the ego applies this period."""

    a_x: np.ndarray  # (B,) at the period's start
    a_y: np.ndarray
    abort: tuple  # (rows, knots, px, vx, py, vy): the aborting rows' exact motion over the period


def chain_analysis(situation: Situation, prm: Params):
    """``(bounds (B, M), unsafe (B,))``: each chain vehicle's worst-case deceleration (Eqs. 1–3, corrected) from
    what the ego knows."""
    n = len(situation)
    m = situation.chain_x.shape[1]
    if situation.err_chain is not None:  # each link at its own worst corner (sensing error)
        s = situation
        return chain_bounds(s.chain_x, s.chain_v, s.chain_promise, s.n_connected, s.chain_human, s.err_chain, prm)
    in_chain = np.arange(m - 1)[None, :] < situation.n_connected[:, None]
    promise = np.where(in_chain, situation.chain_promise, prm.others_decel)
    margin = np.where(situation.chain_human & in_chain, prm.p_m_human, prm.p_m)
    with np.errstate(all="ignore"):  # the situation was validated where it was built: the scan alone
        decel, _, unsafe = propagate_chain(
            ARRAY, situation.chain_x.T, situation.chain_v.T, promise.T, margin.T, prm, m - 1
        )
    bounds = np.column_stack([np.broadcast_to(d, (n,)) for d in decel])
    return bounds, np.broadcast_to(np.asarray(unsafe, bool), (n,))


def exact(s: Situation) -> Situation:
    """The situation with its sensing-error bounds dropped (measurements taken as exact: the paper's shield)."""
    return dataclasses.replace(s, err_f=None, err_chain=None, err_own=None)


def own_leader(s: Situation, cfg: ShieldConfig, prm: Params, informed, broken):
    """``(l0_x, l0_v, l0_decel)`` for the check, or ``None`` (no own-lane leader, or the paper's shield)."""
    if not cfg.own_lane or not s.has_own_lane:
        return None
    return s.own_x[:, 0], s.own_v[:, 0], own_lane_decel(s, prm, informed, broken)


def observe(state, situation: Situation, prm: Params, cfg: ShieldConfig, chain=None) -> Observed:
    """Stage 1. ``state``: the :class:`~.core.ShieldState` of the last period; ``chain``: this situation's
    :func:`chain_analysis` when the caller has it already."""
    state, situation, chain = fold_others(state, situation, prm, cfg, chain)  # others -> F, chain, L0 (world.py)
    belief = ASSESSMENTS[cfg.assessment].update(state.belief, situation, prm.dt, cfg)
    s = situation if cfg.sensing else exact(situation)
    s_eval, s_obs = worst_corners(s)
    bounds, unsafe = chain_analysis(s, prm) if chain is None else chain
    breach = state.breach
    if state.last is not None:
        breach = observe_breaches(state.breach, state.last, s_obs, prm, s.t)
    return Observed(s, s_eval, belief, bounds, unsafe, breach)


def worst_case(obs: Observed, flags, prm: Params, cfg: ShieldConfig) -> WorstCase:
    """Stage 2. ``flags``: the variant's ``(uses_chain, uses_follower_v2x, uses_assessment)``, each ``(B,)``."""
    uses_chain, uses_f_v2x, uses_assessment = flags
    s = obs.situation
    n = len(s)
    assessed = ASSESSMENTS[cfg.assessment].aggressive(obs.belief, s)
    trusted = uses_f_v2x & s.f_connected & s.f_collaborative
    broken = obs.breach.any if cfg.monitor else np.zeros(n, bool)
    l1_decel, f_aggr = worst_case_core(ARRAY, uses_chain, obs.unsafe, obs.bounds[:, 0], prm.others_decel, trusted,
                                       uses_assessment, assessed, broken)  # fmt: skip
    own = own_leader(s, cfg, prm, uses_chain, broken)
    if own is not None:
        own = (obs.evaluated.own_x[:, 0], obs.evaluated.own_v[:, 0], own[2])
    return WorstCase(l1_decel, f_aggr, own)


def worst_case_core(xp, uses_chain, unsafe, l1_bound, a_o, trusted, uses_assessment, assessed, broken):
    """``(l1_decel, f_aggr)``, backend-generic (the one source; the compiled closed loop evaluates it per row): L1
    brakes at its chain bound where the variant uses the chain and the chain is not unsafe, else at the others'
    maximum ``a_o``; F is collaborative where it is trusted (connected, collaborative, and the variant listens), else
    as assessed where the variant assesses, else aggressive; a breach (``broken``) makes both the most conservative."""
    l1_decel = xp.where(broken | unsafe, a_o, xp.where(uses_chain, l1_bound, a_o))
    f_aggr = xp.where(trusted, False, xp.where(uses_assessment, assessed, True))
    return l1_decel, f_aggr | broken


def proposal(raw, n: int, prm: Params, planner_name: str) -> Proposal:
    """Stage 3: ``raw`` is the planner's ``(a_x, a_y)``; see :func:`.proposals.check_proposal`."""
    a_x, a_y, invalid = check_proposal(planner_name, raw, n, prm)
    return Proposal(np.clip(a_x, -prm.a_x_d, prm.a_x_a), np.clip(a_y, -prm.a_y_m, prm.a_y_m), invalid, a_x, a_y)


def frame(state, obs: Observed, worst: WorstCase, prm: Params, cfg: ShieldConfig) -> Frame:
    """Stage 4: with an actuation delay the decision is for the period that starts once the commands in flight
    have acted (:mod:`.realworld`): the ego carried by them exactly, the others by their worst case."""
    s, e = obs.situation, obs.evaluated
    ego = (s.ego_x, s.ego_y, s.ego_vx, s.ego_vy)
    l1, f, own = (e.chain_x[:, 0], e.chain_v[:, 0]), (e.f_x, e.f_v), worst.own
    delay = delay_periods(cfg, prm) * prm.dt
    if delay > 0.0:
        if state.pending is None:
            raise ValueError(f"the shield's state holds no commands in flight, but the config has an actuation delay "
                             f"of {cfg.actuation_delay_s} s: make the state with init(..., config) of the same config")
        ego = state.pending.carry(*ego, prm.dt)
        with np.errstate(over="ignore"):  # (as _motion.advance)
            l1x, l1v, fx, fv = carried_others(ARRAY, *l1, worst.l1_decel, *f, worst.f_aggr, prm.a_x_a, prm.a_x_d,
                                              delay)  # fmt: skip
        l1, f = (l1x, l1v), (fx, fv)
        if own is not None:
            own = (*carry_worst(own[0], own[1], own[2], delay), own[2])
    return Frame(ego, l1, f, own, delay)


def decide(state, obs: Observed, worst: WorstCase, prop: Proposal, fr: Frame, paper_rule, ruled, flags,
           prm: Params, cfg: ShieldConfig) -> Verdicts:  # fmt: skip
    """Stage 5. Rows under the paper's rule: the proposal if its candidate check passes (PROCEED), else the
    hesitation's (HESITATE), else ABORT on the held plan; an invalid proposal is never executed (those rows start
    at the hesitation). ``ruled``: ``[(rule, rows)]`` of other rules (:func:`.rules.rule_rows`), decided by them.
    With the shield disabled every active row proceeds unchecked."""
    n = len(obs.situation)
    ex, ey, evx, evy = fr.ego
    active = ~state.completed
    behaviour = np.where(active, PROCEED, COMPLETED)
    completing = np.zeros(n, bool)
    accepted = []
    a_yh = hesitate_lateral(evy, prm)
    candidates = (ex, ey, evx, evy, prop.a_x, None, *fr.l1, worst.l1_decel, *fr.f, worst.f_aggr)
    if cfg.enabled:
        rows = np.flatnonzero(active & paper_rule)
        skip = rows[:0]
        for code, lateral in ((PROCEED, prop.a_y), (HESITATE, a_yh)):
            if code == PROCEED:
                skip, rows = rows[prop.invalid[rows]], rows[~prop.invalid[rows]]
            elif skip.size:
                rows = np.sort(np.concatenate([rows, skip]))
            if rows.size == 0:
                continue
            args = (lateral if arr is None else arr for arr in candidates)
            verdict = check_candidate(
                *(arr[rows] for arr in args), prm, completion=COMPLETION_RULES[cfg.completion],
                own=None if fr.own is None else tuple(a[rows] for a in fr.own),
            )  # fmt: skip
            ok_rows = rows[verdict.ok]
            behaviour[ok_rows] = code
            completing[ok_rows] = verdict.completing[verdict.ok]
            accepted.extend((rows[idx], plan) for idx, plan in verdict.plans)
            rows = rows[~verdict.ok]
        behaviour[rows] = ABORT
    else:
        completing = active & (ey + evy * prm.dt + 0.5 * prop.a_y * prm.dt * prm.dt >= prm.y_boundary)
    commands = []
    if cfg.enabled:  # the rows of another rule: its decision (an RSS response is an abort without a held plan)
        s = obs.situation
        own = (None, None) if fr.own is None else tuple(np.broadcast_to(a, ex.shape) for a in fr.own[:2])  # L0
        fields = (ex, ey, evx, evy, s.chain_x, s.chain_v, *fr.f, prop.a_x, prop.a_y, a_yh, prop.invalid,
                  worst.l1_decel, flags[0] & ~obs.unsafe, state.completed, obs.bounds, s.n_connected,
                  lane_keep_accel(ARRAY, ey, evy, prm.lane_width, prm.a_y_m), *own)  # fmt: skip
        for rule, idx in ruled:
            behaviour[idx], ax, ay, completing[idx] = rule.decide(
                RuleInputs(*(None if arr is None else arr[idx] for arr in fields)), prm)
            commands.append((idx, ax, ay))
    return Verdicts(behaviour, completing, accepted, a_yh, commands)


def command(state, obs: Observed, worst: WorstCase, prop: Proposal, fr: Frame, verdicts: Verdicts, paper_rule,
            prm: Params) -> Commands:  # fmt: skip
    """Stage 6. Hesitating rows keep the proposal's longitudinal part; after completion the ego centres in the
    target lane and follows L1 responsibly under its worst case; aborting rows follow their held plan exactly (the
    plan's switches inside the period are knots of ``abort``); the rows of another rule take its commands."""
    ex, ey, evx, evy = fr.ego
    l1x, l1v = fr.l1
    behaviour = verdicts.behaviour
    ax_cmd = prop.a_x.copy()
    ay_cmd = np.where(behaviour == HESITATE, verdicts.a_yh, prop.a_y)
    done = np.flatnonzero(state.completed & paper_rule)
    if done.size:
        slack, l1d = (l1x - ex - prm.p_m)[done], worst.l1_decel[done]
        ax_cmd[done] = responsible_accel(prop.a_x[done], slack, evx[done], l1v[done], l1d, prm)
        soft = l1d > prm.a_x_d  # L1 may brake harder than the ego: the closed form is confirmed by the exact check
        if soft.any():
            r = done[soft]
            with np.errstate(all="ignore"):
                ok = responsible_ok(ax_cmd[r], slack[soft], evx[r], l1v[r], l1d[soft], prm, tol=FEASIBILITY_TOL_M)
            ax_cmd[r] = np.where(ok, ax_cmd[r], -prm.a_x_d)
        ay_cmd[done] = lane_keep_accel(ARRAY, ey[done], evy[done], prm.lane_width, prm.a_y_m)
    abort_rows = np.flatnonzero((behaviour == ABORT) & paper_rule)
    abort = (abort_rows, None, None, None, None, None)
    if abort_rows.size:  # only the aborting rows follow their plan: evaluate it there alone
        age = np.maximum(obs.situation.t + fr.delay_s - state.plan_t0[abort_rows], 0.0)  # (round-off of the sums)
        knots, px, vx, py, vy = plan_motion(state.plan.take(abort_rows), age, prm.dt)
        abort = (abort_rows, knots, px, vx, py, vy)
        # The accelerations at the period's start: the first segment of positive length (switches already past
        # leave zero-length segments at the front; the knots span the period, so one segment has length dt > 0).
        first = np.argmax(np.diff(knots, axis=1) > 0.0, axis=1)
        r = np.arange(abort_rows.size)
        span = knots[r, first + 1] - knots[r, first]
        ax_cmd[abort_rows] = (vx[r, first + 1] - vx[r, first]) / span
        ay_cmd[abort_rows] = (vy[r, first + 1] - vy[r, first]) / span
    for idx, ax, ay in verdicts.ruled:
        ax_cmd[idx], ay_cmd[idx] = ax, ay
    return Commands(ax_cmd, ay_cmd, abort)


def lane_keep_accel(xp, ego_y, ego_vy, lane_width, a_y_m):
    """After completion: the lateral acceleration that centres the ego in the target lane (a PD law, gains 0.8 s⁻²
    and 1.6 s⁻¹: critically damped), within ``±a_y_m``. Backend-generic, the one source (the compiled closed loop
    evaluates it per row)."""
    return xp.clip(0.8 * (lane_width - ego_y) - 1.6 * ego_vy, -a_y_m, a_y_m)


def remember(state, obs: Observed, worst: WorstCase, fr: Frame, verdicts: Verdicts, prm: Params):
    """Stage 7: ``(plan, plan_t0, plan_f_aggr, snapshot, breach)`` for the next period. The plans accepted replace
    the held ones; the monitor's snapshot holds the states at the period's start (not carried over the delay), the
    chain's bounds, the plan's assumptions and — for an F the held plan takes for collaborative, with the ego
    ahead — the strongest braking a responsible follower of the ego could use this period."""
    s, e = obs.situation, obs.evaluated
    n = len(s)
    active = ~state.completed
    new_plan = set_rows(state.plan, verdicts.accepted)
    replanned = (verdicts.behaviour == PROCEED) | (verdicts.behaviour == HESITATE)
    plan_t0 = np.where(replanned, s.t + fr.delay_s + prm.dt, state.plan_t0)
    plan_f_aggr = state.plan_f_aggr.copy()
    for rows_acc, _ in verdicts.accepted:
        plan_f_aggr[rows_acc] = worst.f_aggr[rows_acc]
    f_limit = np.full(n, np.inf)
    sfx, sfv, sex = e.f_x, e.f_v, s.ego_x
    watch = np.flatnonzero(active & ~plan_f_aggr & (sex - sfx > 0.0))
    if watch.size:
        # The most a responsible F may accelerate (the ego brakes at most a_x_d, F itself up to a_o_d), at the corner
        # of the sensing box that allows it the most — F low and slow, the observed corner — so that a measurement
        # error is never taken for a breach: at the analysis' corner (F high and fast) the gap can be below the
        # margin where F's true one is not, and the limit -a_o_d that no responsible F has to obey. The prediction
        # starts from the analysis' corner (monitor.pushed_harder): the box is counted on both sides.
        lo = worst_corners(s)[1]
        with np.errstate(all="ignore"):
            gap = (sex - lo.f_x - prm.p_m)[watch]
            limit = responsible_bound(gap, lo.f_v[watch], s.ego_vx[watch], np.full(watch.size, prm.a_x_d), prm,
                                      brake=prm.others_decel)  # fmt: skip
        f_limit[watch] = np.maximum(limit, -prm.others_decel)
    anchor = None
    if s.err_chain is not None or s.err_f is not None:  # a sensing box: the cumulative comparison (monitor.py)
        now = Anchor(
            t=np.full(n, float(s.t)), f_t=np.full(n, float(s.t)), own_t=np.full(n, float(s.t)),
            chain_x=e.chain_x, chain_v=e.chain_v, bounds=obs.bounds,
            l1_decel=np.asarray(new_plan.l1_decel, float), n_connected=s.n_connected, f_x=sfx, f_v=sfv,
            f_accel=np.where(plan_f_aggr, prm.a_x_a, np.inf),
            own_x=np.full(n, np.inf) if worst.own is None else np.asarray(worst.own[0], float),
            own_v=np.zeros(n) if worst.own is None else np.asarray(worst.own[1], float),
            own_decel=np.zeros(n) if worst.own is None else np.asarray(worst.own[2], float),
        )  # fmt: skip
        held = None if state.last is None else state.last.anchor
        anchor = now if held is None else held.carried(now)
    snapshot = Snapshot(
        chain_x=e.chain_x, chain_v=e.chain_v, bounds=obs.bounds, n_connected=s.n_connected, f_x=sfx, f_v=sfv,
        f_limit=f_limit, plan_l1_decel=new_plan.l1_decel, plan_f_aggr=plan_f_aggr, active=active, anchor=anchor,
    )  # fmt: skip
    breach = obs.breach
    if s.v2x_stale is not None:
        breach = with_stale(breach, active & s.v2x_stale, s.t)
    return new_plan, plan_t0, plan_f_aggr, snapshot, breach


def with_stale(breach: Breach, stale, t: float) -> Breach:
    """``breach`` with the rows whose V2X messages went stale this period flagged (``stale_v2x``)."""
    col = BREACH_KINDS.index("stale_v2x")
    new = stale & ~breach.flags[:, col]
    if not new.any():
        return breach
    flags = breach.flags.copy()
    flags[:, col] |= stale
    first = np.where(np.isnan(breach.first_s) & new, t, breach.first_s)
    return Breach(flags=flags, first_s=first)


jitable(worst_case_core, lane_keep_accel)
