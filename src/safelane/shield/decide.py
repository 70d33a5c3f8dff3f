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

from .._motion import advance, free_max
from ..params import Params
from ..safety._backend import ARRAY
from ..safety.chain import min_follow_decel
from ..safety.evasion import evasion_core, fast_kernel
from ..safety.lateral import LATERAL_TOL_M, lateral_core
from ..safety.longitudinal import FEASIBILITY_TOL_M
from ..safety.own_lane import own_lane_core
from ..safety.plan import EvasionPlan, plan_from_core
from ..safety.responsible import pair_min_gap

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
    z_l = min_follow_decel(ARRAY, lx - ex - prm.p_m, evx, lv, l1_decel)
    z_f = min_follow_decel(ARRAY, ex - fx - prm.p_m, fv, evx, prm.a_x_d)
    return (z_l <= prm.a_x_d) & (z_f <= prm.a_x_d)


def own_completion_level(prm: Params) -> float:
    """With a leader ``L0`` in the own lane, the lane change completes (and ``L0`` stops counting) when the ego's
    centre is past the lane boundary *and* its body can no longer overlap ``L0``'s laterally (``y >= w_v``), moving
    away from it or not at all laterally (``v_y >= 0``: the lane-keeping after completion then never brings it
    back below that level)."""
    return max(prm.y_boundary, prm.vehicle_width)


def own_margin(prm: Params) -> float:
    """The margin the evasion keeps to ``L0``: ``p_m`` plus half the feasibility tolerance (see check_candidate)."""
    return prm.p_m + 0.5 * FEASIBILITY_TOL_M


#: :func:`check_candidate` runs the compiled kernel (:mod:`._fast_decide`) for batches of at least this many rows.
FAST_CANDIDATE_MIN = 32


def candidate_kernel():
    """The compiled candidate check's module :mod:`._fast_decide`, or ``None`` where
    :func:`~safelane.safety.evasion.fast_kernel` is ``None`` (numba missing, or ``SAFELANE_NO_NUMBA=1``)."""
    if fast_kernel() is None:
        return None
    from . import _fast_decide

    return _fast_decide


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
    only at :func:`own_completion_level`. Without ``own``, batches of :data:`FAST_CANDIDATE_MIN` rows or more run
    the compiled kernel (:mod:`._fast_decide`) where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``: the same
    bits as the NumPy path below, the reference."""
    if own is None and np.size(ego_x) >= FAST_CANDIDATE_MIN and (kernel := candidate_kernel()) is not None:
        return kernel.check_candidate(
            ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive, prm, completion
        )
    dt, tol = prm.dt, FEASIBILITY_TOL_M
    ex, evx = advance(ego_x, ego_vx, a_x, dt)
    ey = ego_y + ego_vy * dt + 0.5 * a_y * dt * dt
    evy = ego_vy + a_y * dt
    lx, lv = advance(l1_x, l1_v, -l1_decel, dt)
    a_f = np.where(f_aggressive, prm.a_x_a, -prm.a_x_d)
    fx, fv = advance(f_x, f_v, a_f, dt)

    conflict = free_max(ego_y, ego_vy, a_y, dt) > prm.y_safe + LATERAL_TOL_M
    # Both worst-case gaps (ego behind L1, F behind the ego) over the period, in one stacked evaluation.
    gap_l, gap_f = pair_min_gap(
        np.stack([l1_x - ego_x - prm.p_m, ego_x - f_x - prm.p_m]),
        np.stack([ego_vx, f_v]),
        np.stack([a_x, a_f]),
        np.stack([l1_v, ego_vx]),
        np.stack([-l1_decel, a_x]),
        dt,
    )
    period_ok = ~conflict | ((gap_l >= -tol) & (gap_f >= -tol))
    has_own = None
    if own is not None:
        o_x, o_v, o_decel = own
        has_own = np.isfinite(o_x)
        if not has_own.any():
            has_own = None
    base = completion.level(prm) if hasattr(completion, "level") else prm.y_boundary  # where the step completes
    level = base
    if has_own is not None:
        o_slack = np.where(has_own, o_x - ego_x - prm.p_m, 0.0)
        gap_o = pair_min_gap(o_slack, ego_vx, a_x, np.where(has_own, o_v, 0.0), -o_decel, dt)
        # Half the tolerance for L0, here and in the evasion (OWN_MARGIN_M): a follower of L0 settles exactly at the
        # margin, and the executor's round-off must stay inside the tolerance.
        period_ok &= ~has_own | (gap_o >= -0.5 * tol)
        level = np.where(has_own, max(own_completion_level(prm), base), base)
        ox, ov = advance(np.where(has_own, o_x, 0.0), o_v, -o_decel, dt)

    completing = ey >= level
    if has_own is not None:  # with L0 a completed lane change must not drift back toward it: moving away, or still
        completing &= ~has_own | (evy >= 0.0)
    n = np.shape(ex)
    ok = np.zeros(n, bool)
    plans = []
    with np.errstate(all="ignore"):
        guard = np.ones(n, bool)
        done = np.flatnonzero(completing)  # the completion guard replaces the evasion check (few rows)
        if done.size:
            guard[done] = completion(*(a[done] for a in (ex, evx, lx, lv, l1_decel, fx, fv)), prm)
        args = (ex, ey, evx, evy, lx, lv, l1_decel, fx, fv, f_aggressive)
        # Rows with nothing to evade (in the own lane, not moving out: t_y_f = 0) go through the evasion core
        # apart: with t_y_f = 0 throughout it takes its short path (same results).
        idle = lateral_core(ARRAY, ey, evy, prm)[0] == 0.0
        if has_own is not None:  # rows with L0 go through the own-lane check (the others as before, bit for bit)
            idle = idle & ~has_own
        groups = [np.arange(n[0])] if idle.all() or not idle.any() else [np.flatnonzero(idle), np.flatnonzero(~idle)]
        if has_own is not None:
            groups = [g[~has_own[g]] for g in groups] + [np.flatnonzero(has_own)]
        for rows in groups:
            if rows.size == 0:
                continue
            sub_args = tuple(a[rows] for a in args)
            own_rows = has_own is not None and bool(has_own[rows[0]])
            if own_rows:
                own_args = (ox[rows], ov[rows], o_decel[rows])
                exists, parts = own_lane_core(*sub_args, *own_args, prm.p_m, prm.p_m, own_margin(prm), prm)
            else:
                exists, parts = evasion_core(ARRAY, *sub_args, prm.p_m, prm.p_m, prm)
            # A rule with ``needs_evasion`` (the paper's) keeps the evasion check at the crossing step as well.
            cross_ok = guard[rows] & (exists | (not getattr(completion, "needs_evasion", False)))
            keep = np.flatnonzero(period_ok[rows] & np.where(completing[rows], cross_ok, exists))
            ok[rows[keep]] = True
            plan = plan_from_core(
                ARRAY,
                keep.shape,
                (*(a[keep] for a in sub_args), prm.p_m, prm.p_m),
                exists[keep],
                {k: np.broadcast_to(v, rows.shape)[keep] for k, v in parts.items()},
                prm.p_m,
                prm.p_m,
                prm,
                own=(*(a[keep] for a in own_args), own_margin(prm)) if own_rows else None,
            )
            plans.append((rows[keep], plan))
    return Verdict(ok=ok, completing=completing, plans=plans)


def hesitate_lateral(ego_vy, prm: Params):
    """Lateral acceleration driving the lateral speed to zero within a period (as far as ``a_y_m`` allows)."""
    return np.clip(-ego_vy / prm.dt, -prm.a_y_m, prm.a_y_m)


def plan_motion(plan: EvasionPlan, age, dt: float):
    """Exact longitudinal and lateral motion of the ego executing ``plan`` on ``[age, age + dt]``, as knots
    ``(t, px, vx, py, vy)`` (``(..., 8)`` each; ``t`` relative to the period's start).

    Knots: the period's ends and every switch of the plan inside it (``t_x1``, end of braking, L1's stop,
    ``t_y_f``, the lateral switch and end), so each segment has constant accelerations.
    """
    _, lead_v, lead_decel = plan.lead
    l1_stop = np.where(lead_decel > 0.0, lead_v / np.where(lead_decel > 0.0, lead_decel, 1.0), np.inf)
    switches = [plan.t_x1, plan.t_brake_end, l1_stop, plan.t_y_f, plan.t_y_switch, plan.t_y_end]
    rel = [np.clip(s - age, 0.0, dt) for s in switches]
    knots = np.sort(np.stack([np.zeros_like(age), *rel, np.full_like(age, dt)], -1), -1)
    px, py, vx, vy = plan.take((..., None)).state(age[..., None] + knots)
    return knots, px, vx, py, vy
