"""The shield's decision (paper §3.1): proceed, hesitate, or abort — every control period.

Each period, in strictly decreasing preference:

1. **proceed** — apply the nominal planner's ``(a_x, a_y)`` for one period, predicting L1 and F at their worst
   case over it (L1 braking at its worst-case deceleration, F at ``+a_x_a`` if assumed aggressive, ``−a_x_d``
   if collaborative); accept if a safe evasion exists from the predicted state;
2. **hesitate** — the same with the lateral acceleration that drives the lateral speed to zero;
3. **abort** — execute the evasion plan verified in an earlier period, exactly.

Invariant: the ego always holds a verified plan. Two checks go beyond the paper's text, both needed for the
invariant to hold in continuous time:

* *within the period*: while the ego is in the conflict zone at any instant of the period, both worst-case gaps
  must stay ``>= p_m`` during the period itself (exact minimum), not only at its ends;
* *completion guard*: a step that would take the ego's centre across the lane boundary commits the ego to the
  target lane, so instead of an evasion back it requires that the ego can keep ``p_m`` behind L1's worst case
  and a worst-case F can keep ``p_m`` behind the ego, both by braking at no more than ``a_x_d``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._motion import advance_core
from ..params import Params
from ..safety._backend import ARRAY, INF, jitable
from ..safety.chain import min_follow_decel
from ..safety.evasion import PARTS, evasion_parts, fast_kernel
from ..safety.lateral import LATERAL_TOL_M
from ..safety.longitudinal import FEASIBILITY_TOL_M
from ..safety.own_lane import own_lane_core, own_period
from ..safety.plan import EvasionPlan, plan_from_core
from ..safety.responsible import pair_min_gap_core

#: The supervisor's choice per step (the trace's ``behaviour``); ``COMPLETED``: the lane change is done.
PROCEED, HESITATE, ABORT, COMPLETED = 0, 1, 2, -1


@dataclass(frozen=True)
class Verdict:
    """Outcome of checking one candidate action for every scenario of the batch."""

    ok: np.ndarray
    completing: np.ndarray
    plans: list[tuple[np.ndarray, EvasionPlan]]  # (accepted rows, their plans), covering ``ok``'s True rows


def commit_guard(ex, evx, lx, lv, l1_decel, fx, fv, prm: Params):
    """The completion rule ``commit_guard``: a step that takes the ego's centre across the lane boundary commits it
    to the target lane, so it needs the ego able to keep ``p_m`` behind L1's worst case and a worst-case F able to
    keep ``p_m`` behind the ego, each braking at no more than ``a_x_d`` (arguments: the predicted states at the end
    of the period, rows that complete)."""
    return commit_guard_core(ARRAY, ex, evx, lx, lv, l1_decel, fx, fv, prm.p_m, prm.a_x_d, FEASIBILITY_TOL_M)


def commit_guard_core(xp, ex, evx, lx, lv, l1_decel, fx, fv, p_m, a_x_d, tol):
    """:func:`commit_guard`, backend-generic (the one source; the compiled closed loop evaluates it per row)."""
    z_l = min_follow_decel(xp, lx - ex - p_m, evx, lv, l1_decel, tol)
    z_f = min_follow_decel(xp, ex - fx - p_m, fv, evx, a_x_d, tol)
    return (z_l <= a_x_d) & (z_f <= a_x_d)


def own_completion_level(prm: Params) -> float:
    """With a leader ``L0`` in the own lane, the lane change completes (and ``L0`` stops counting) when the ego's
    centre is past the lane boundary *and* its body can no longer overlap ``L0``'s laterally (``y >= w_v``), moving
    away from it or not at all laterally (``v_y >= 0``: the lane-keeping after completion then never brings it
    back below that level)."""
    return max(prm.y_boundary, prm.vehicle_width)


def own_margin(prm: Params) -> float:
    """The margin the evasion keeps to ``L0``: ``p_m`` plus half the feasibility tolerance (see check_candidate)."""
    return prm.p_m + 0.5 * FEASIBILITY_TOL_M


def lateral_max(xp, y0, vy0, a, y_end, dt):
    """Exact maximum over ``[0, dt]`` of ``y0 + vy0 t + a t²/2`` (one free segment, ending at ``y_end``): the ends,
    and the vertex where it lies inside the period. Backend-generic; the one home of the conflict zone's test (the
    candidate's period here, the delay's commands in :mod:`.realworld`, the checks' lateral extent)."""
    tau = xp.where(a < 0.0, xp.div(-vy0, a, 0.0), -1.0)
    vertex = xp.where((tau > 0.0) & (tau < dt), y0 + 0.5 * vy0 * tau, -INF)
    return xp.maximum(xp.maximum(y0, y_end), vertex)


def candidate_period(xp, ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive, prm, p_m,
                     dt, level, lat_tol, tol):  # fmt: skip
    """The period at the candidate ``(a_x, a_y)`` with L1 and F at their worst case (L1 braking at ``l1_decel``, F at
    ``+a_x_a`` if aggressive, else ``−a_x_d``; exact motion stopping at rest), backend-generic. Returns
    ``(state, period_ok, completing)``: the predicted states ``(ex, ey, evx, evy, lx, lv, fx, fv)`` at the period's
    end; whether the period keeps both worst-case gaps (ego behind L1, F behind the ego) ``>= p_m`` to ``tol`` at
    every instant, required only where the ego is in the conflict zone at some instant (lateral maximum above
    ``y_safe + lat_tol``); whether the step completes (``ey >= level``). ``prm``: ``Params`` or its ``Limits``."""
    ex, evx = advance_core(xp, ego_x, ego_vx, a_x, dt)
    ey = ego_y + ego_vy * dt + 0.5 * a_y * dt * dt
    evy = ego_vy + a_y * dt
    lx, lv = advance_core(xp, l1_x, l1_v, -l1_decel, dt)
    a_f = xp.where(f_aggressive, prm.a_x_a, -prm.a_x_d)
    fx, fv = advance_core(xp, f_x, f_v, a_f, dt)
    conflict = lateral_max(xp, ego_y, ego_vy, a_y, ey, dt) > prm.y_safe + lat_tol
    gap_l = pair_min_gap_core(xp, l1_x - ego_x - p_m, ego_vx, a_x, l1_v, -l1_decel, dt)
    gap_f = pair_min_gap_core(xp, ego_x - f_x - p_m, f_v, a_f, ego_vx, a_x, dt)
    period_ok = xp.where(conflict, (gap_l >= -tol) & (gap_f >= -tol), True)
    return (ex, ey, evx, evy, lx, lv, fx, fv), period_ok, ey >= level


def candidate_row(xp, ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive, prm, p_m,
                  dt, level, lat_tol, tol):  # fmt: skip
    """The candidate check without an own-lane leader, backend-generic: :func:`candidate_period`, then the evasion
    check with its plan from the predicted state (:func:`~safelane.safety.evasion.evasion_parts`, margins ``p_m``).
    Returns ``(state, period_ok, completing, evasion)``, ``evasion`` as ``evasion_parts`` returns it. The one source
    of the check: :func:`check_candidate` evaluates it on NumPy arrays, :mod:`._fast_decide` compiled, row by row
    (also inside the compiled closed loop)."""
    state, period_ok, completing = candidate_period(
        xp, ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive, prm, p_m, dt,
        level, lat_tol, tol,
    )  # fmt: skip
    ex, ey, evx, evy, lx, lv, fx, fv = state
    evasion = evasion_parts(xp, ex, ey, evx, evy, lx, lv, l1_decel, fx, fv, f_aggressive, p_m, p_m, prm, tol)
    return state, period_ok, completing, evasion


#: :func:`check_candidate` runs the compiled kernel (:mod:`._fast_decide`) for batches of at least this many rows:
#: every batch (measured with ``benchmarks/bench_shield_latency.py``'s situation: one vehicle's ``Shield.step`` about
#: 2.4x faster than with the NumPy path below 32 rows). The threshold stays so a test can see where the dispatch
#: switches.
FAST_CANDIDATE_MIN = 1


def candidate_kernel():
    """The compiled candidate check's module :mod:`._fast_decide`, or ``None`` where
    :func:`~safelane.safety.evasion.fast_kernel` is ``None`` (numba missing, or ``SAFELANE_NO_NUMBA=1``)."""
    if fast_kernel() is None:
        return None
    from . import _fast_decide

    return _fast_decide


def own_kernel():
    """The compiled own-lane check's module :mod:`._fast_own` (the rows with ``L0`` of :func:`check_candidate`, every
    batch size), or ``None`` where :func:`~safelane.safety.evasion.fast_kernel` is ``None`` (numba missing, or
    ``SAFELANE_NO_NUMBA=1``): then the NumPy block of :func:`_with_own`, the same functions on arrays."""
    if fast_kernel() is None:
        return None
    from . import _fast_own

    return _fast_own


def completion_level(completion, prm: Params) -> float:
    """Where a step completes under the rule ``completion`` (its ``level``, else the lane boundary)."""
    return completion.level(prm) if hasattr(completion, "level") else prm.y_boundary


def check_candidate(
    ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive, prm: Params,
    completion=commit_guard, own=None,
) -> Verdict:  # fmt: skip
    """Is applying ``(a_x, a_y)`` for one period safe under the worst case? Returns the verdict and, for the rows
    it accepts, the plan verified from the predicted state (time origin at the end of the period). ``completion``:
    the completion rule for rows whose step crosses the lane boundary (a registered one, see
    :mod:`safelane.shield.policies`). ``own``: ``(l0_x, l0_v, l0_decel)`` of the own-lane leader ``L0`` per row
    (``+inf`` position where there is none), or ``None``: where there is one, the ego must keep ``p_m`` behind its
    worst case during the period and on the evasion (:mod:`safelane.safety.own_lane`), and the step completes
    only at :func:`own_completion_level`.

    The rows without ``L0`` are :func:`candidate_row`: batches of :data:`FAST_CANDIDATE_MIN` rows or more run it
    compiled (:mod:`._fast_decide`) where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``, smaller ones and
    every batch without numba on NumPy arrays."""
    args = np.broadcast_arrays(*(np.asarray(a) for a in (ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v,
                                                          l1_decel, f_x, f_v, f_aggressive)))  # fmt: skip
    has_own = None if own is None else np.isfinite(own[0])
    if has_own is not None and has_own.any():
        return _with_own(args, has_own, own, prm, completion)
    if np.size(ego_x) >= FAST_CANDIDATE_MIN and (kernel := candidate_kernel()) is not None:
        return kernel.check_candidate(*args, prm, completion)
    with np.errstate(all="ignore"):
        state, period_ok, completing, (exists, *fields) = candidate_row(
            ARRAY, *args, prm, prm.p_m, prm.dt, completion_level(completion, prm), LATERAL_TOL_M, FEASIBILITY_TOL_M
        )
    parts = dict(zip(PARTS, fields, strict=True))
    return verdict_of(state, period_ok, completing, exists, parts, args[8], args[11], prm, completion)


def verdict_of(state, period_ok, completing, exists, parts, l1_decel, f_aggressive, prm: Params, completion, own=None):
    """The :class:`Verdict` of rows checked by :func:`candidate_row` (or, with ``own``, the own-lane check): a row is
    accepted where its period is safe and, if its step completes, the completion rule holds (and, for a rule with
    ``needs_evasion``, the evasion exists), else the evasion exists; its plan is built from the predicted state.
    ``own``: ``(l0_x, l0_v, l0_decel, margin)`` at the period's end, or ``None``."""
    ex, ey, evx, evy, lx, lv, fx, fv = state
    n = np.shape(ex)
    guard = np.ones(n, bool)
    done = np.flatnonzero(completing)  # the completion rule replaces the evasion check (few rows)
    with np.errstate(all="ignore"):
        if done.size:
            guard[done] = completion(*(a[done] for a in (ex, evx, lx, lv, l1_decel, fx, fv)), prm)
        # A rule with ``needs_evasion`` (the paper's) keeps the evasion check at the crossing step as well.
        cross_ok = guard & (exists | (not getattr(completion, "needs_evasion", False)))
        keep = np.flatnonzero(period_ok & np.where(completing, cross_ok, exists))
        plan = plan_from_core(
            ARRAY,
            keep.shape,
            (*(a[keep] for a in (ex, ey, evx, evy, lx, lv, l1_decel, fx, fv, f_aggressive)), prm.p_m, prm.p_m),
            exists[keep],
            {k: (v if np.shape(v) == n else np.broadcast_to(v, n))[keep] for k, v in parts.items()},
            prm.p_m,
            prm.p_m,
            prm,
            own=None if own is None else (*(a[keep] for a in own[:3]), own[3]),
        )
    ok = np.zeros(n, bool)
    ok[keep] = True
    return Verdict(ok=ok, completing=np.asarray(completing, bool).copy(), plans=[(keep, plan)])


def _with_own(args, has_own, own, prm: Params, completion) -> Verdict:
    """:func:`check_candidate` of a batch with ``L0`` in some rows: the others as without ``own``; the rows with
    ``L0`` through the period at the candidate, ``L0``'s gap over it and the own-lane evasion check."""
    n = has_own.shape
    ok, completing, plans = np.zeros(n, bool), np.zeros(n, bool), []
    plain = np.flatnonzero(~has_own)
    if plain.size:
        sub = check_candidate(*(a[plain] for a in args), prm, completion)
        ok[plain], completing[plain] = sub.ok, sub.completing
        plans.extend((plain[rows], plan) for rows, plan in sub.plans)
    rows = np.flatnonzero(has_own)
    ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggr = (a[rows] for a in args)
    o_x, o_v, o_decel = (np.broadcast_to(a, n)[rows] for a in own)
    dt, tol = prm.dt, FEASIBILITY_TOL_M
    # With L0 the lane change completes only at own_completion_level, and only moving away from L0 (or not at all
    # laterally): the lane-keeping after completion then never brings the ego back toward it.
    level = max(own_completion_level(prm), completion_level(completion, prm))
    if (kernel := own_kernel()) is not None:  # the same functions, compiled row by row (shield/_fast_own.py)
        state, period_ok, done, (ox, ov), exists, parts = kernel.check_own(
            (ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggr), (o_x, o_v, o_decel), prm,
            level,
        )  # fmt: skip
    else:
        with np.errstate(all="ignore"):
            state, period_ok, done = candidate_period(
                ARRAY, ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggr, prm, prm.p_m,
                dt, level, LATERAL_TOL_M, tol,
            )  # fmt: skip
            period_ok, done, ox, ov = own_period(ARRAY, ego_x, ego_vx, a_x, o_x, o_v, o_decel, period_ok, done,
                                                 state[3], prm.p_m, dt, tol)  # fmt: skip
            ex, ey, evx, evy, lx, lv, fx, fv = state
            exists, parts = own_lane_core(ex, ey, evx, evy, lx, lv, l1_decel, fx, fv, f_aggr, ox, ov, o_decel,
                                          prm.p_m, prm.p_m, own_margin(prm), prm)  # fmt: skip
    sub = verdict_of(state, period_ok, done, exists, parts, l1_decel, f_aggr, prm, completion,
                  own=(ox, ov, o_decel, own_margin(prm)))  # fmt: skip
    ok[rows], completing[rows] = sub.ok, sub.completing
    plans.extend((rows[r], plan) for r, plan in sub.plans)
    return Verdict(ok=ok, completing=completing, plans=plans)


def hesitate_lateral(ego_vy, prm: Params):
    """Lateral acceleration driving the lateral speed to zero within a period (as far as ``a_y_m`` allows)."""
    return hesitate_core(ARRAY, ego_vy, prm.dt, prm.a_y_m)


def hesitate_core(xp, ego_vy, dt, a_y_m):
    """:func:`hesitate_lateral`, backend-generic (the one source; the compiled closed loop evaluates it per row)."""
    return xp.clip(-ego_vy / dt, -a_y_m, a_y_m)


def plan_motion(plan: EvasionPlan, age, dt: float):
    """Exact longitudinal and lateral motion of the ego executing ``plan`` on ``[age, age + dt]``, as knots
    ``(t, px, vx, py, vy)`` (``(..., 8)`` each; ``t`` relative to the period's start).

    Knots: the period's ends and every switch of the plan inside it (``t_x1``, end of braking, L1's stop,
    ``t_y_f``, the lateral switch and end), so each segment has constant accelerations.
    """
    _, lead_v, lead_decel = plan.lead
    rel = plan_switches(ARRAY, plan, lead_v, lead_decel, age, dt)
    knots = np.sort(np.stack([np.zeros_like(age), *rel, np.full_like(age, dt)], -1), -1)
    px, py, vx, vy = plan.take((..., None)).state(age[..., None] + knots)
    return knots, px, vx, py, vy


def plan_switches(xp, plan, lead_v, lead_decel, age, dt):
    """The switches of ``plan`` as instants of the period ``[age, age + dt]`` (relative to its start, clipped to
    ``[0, dt]``): ``t_x1``, the end of braking, the stop of the vehicle it follows (``lead_v``, braking at
    ``lead_decel``; never where it does not brake), ``t_y_f``, the lateral switch and end — :func:`plan_motion`'s
    inner knots. ``plan``: an ``EvasionPlan`` or a ``PlanRecord``. Backend-generic (the compiled closed loop's held
    plan, row by row)."""
    braking = lead_decel > 0.0
    l1_stop = xp.where(braking, lead_v / xp.where(braking, lead_decel, 1.0), INF)
    return (
        xp.clip(plan.t_x1 - age, 0.0, dt),
        xp.clip(plan.t_brake_end - age, 0.0, dt),
        xp.clip(l1_stop - age, 0.0, dt),
        xp.clip(plan.t_y_f - age, 0.0, dt),
        xp.clip(plan.t_y_switch - age, 0.0, dt),
        xp.clip(plan.t_y_end - age, 0.0, dt),
    )


# The candidate check compiled into the shield's kernel and the closed loop, the held plan's switches into the closed
# loop (safety/_compile.py): the same functions.
jitable(lateral_max, candidate_period, candidate_row, plan_switches, commit_guard_core, hesitate_core)
