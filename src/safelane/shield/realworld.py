"""What the shield does beyond the paper's world (real_roads.md): sensing error, the own lane's chain, actuation delay.

* **Sensing error** (:func:`worst_corners`): every measured state lies within its bound of the truth. The analysis is
  monotone in each vehicle's state, with a known direction: a leader (``L1``, ``L0``) lower and slower is worse for
  the ego, ``F`` higher and faster is worse. So the analysis runs on those corners. The chain analysis is not
  monotone per vehicle (``L_i`` is the follower of one link and the leader of the next), so each *link* takes its
  own worst corner — its slack shrunk by both bounds, the follower faster, the leader slower
  (:func:`chain_bounds`): a bound at least as large as the largest over all consistent corners (sound, possibly
  conservative; ``tests/test_realworld.py`` samples the box).
* **The own lane** (:func:`own_lane_decel`): ``L0``'s worst-case deceleration is its chain's bound where ``L0`` is
  connected (the same analysis, Eqs. 1–3, on the own lane's chain), else ``a_x_d``.
* **Actuation delay** δ = d periods (:class:`~.command.InFlight`): a command acts d periods after it is issued.
  The shield keeps the commands in flight; the ego's state when the new command starts acting is its measured
  state carried through them, exactly, and the others' worst cases are carried over δ along their worst-case
  trajectories. The candidate is then checked from there — the first δ of every evasion trajectory is the
  commands already issued.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._motion import advance_core
from ..params import Params
from ..safety._backend import ARRAY, FEASIBILITY_TOL_M, INF, jitable
from ..safety.chain import chain_link
from ..safety.lateral import LATERAL_TOL_M
from ..safety.own_lane import own_lane_core
from ..safety.plan import EvasionPlan, plan_from_core, set_rows
from ..safety.responsible import pair_min_gap
from ..tolerances import TIME_TOL_S
from .decide import lateral_max, own_kernel, own_margin
from .situation import Situation


def _err(arr, shape):
    return np.zeros((*shape, 2)) if arr is None else arr


def worst_corners(s: Situation) -> tuple[Situation, Situation]:
    """``(analysis, observed)``: the situation at the corners the analysis must assume (leaders low and slow, F
    high and fast) and at the opposite corners (what the monitor compares a new observation with, so that a
    measurement error is never taken for a breach). Without error bounds both are ``s``. Each vehicle's corner is
    :func:`behind_corner` or :func:`ahead_corner` (the compiled period evaluates them per row)."""
    if not s.has_errors:
        return s, s
    b, m = s.chain_x.shape
    ef, ec = _err(s.err_f, (b,)), _err(s.err_chain, (b, m))
    lx, lv = behind_corner(ARRAY, s.chain_x, s.chain_v, ec[..., 0], ec[..., 1])
    fx, fv = ahead_corner(ARRAY, s.f_x, s.f_v, ef[:, 0], ef[:, 1])
    low = dict(chain_x=lx, chain_v=lv, f_x=fx, f_v=fv)
    hx, hv = ahead_corner(ARRAY, s.chain_x, s.chain_v, ec[..., 0], ec[..., 1])
    fx, fv = behind_corner(ARRAY, s.f_x, s.f_v, ef[:, 0], ef[:, 1])
    high = dict(chain_x=hx, chain_v=hv, f_x=fx, f_v=fv)
    if s.own_x is not None:
        eo = _err(s.err_own, s.own_x.shape)
        ox, ov = behind_corner(ARRAY, s.own_x, s.own_v, eo[..., 0], eo[..., 1])
        low.update(own_x=ox, own_v=ov)
        ox, ov = ahead_corner(ARRAY, s.own_x, s.own_v, eo[..., 0], eo[..., 1])
        high.update(own_x=ox, own_v=ov)
    return dataclasses.replace(s, **low), dataclasses.replace(s, **high)


def behind_corner(xp, x, v, err_x, err_v):
    """``(x, v)``: a vehicle measured at ``(x, v)`` within ``(err_x, err_v)`` at the box's corner behind and slower
    (speeds stay at or above zero). Backend-generic, the one source (the compiled period evaluates it per row)."""
    return x - err_x, xp.maximum(v - err_v, 0.0)


def ahead_corner(xp, x, v, err_x, err_v):
    """``(x, v)``: the box's corner ahead and faster (:func:`behind_corner`'s opposite). Backend-generic."""
    return x + err_x, v + err_v


def link_at_corner(xp, x_f, v_f, err_f_x, err_f_v, x_l, v_l, err_l_x, err_l_v, margin, a_ahead, promise, a_o):
    """``(decel, broken)`` of one chain link (:func:`~safelane.safety.chain.chain_link`) at its own worst corner: the
    slack shrunk by both position bounds, the follower ``(x_f, v_f)`` faster, the leader ``(x_l, v_l)`` slower (the
    module docstring); a slack of NaN (both slots empty, ``+inf`` positions) leaves the link free. Backend-generic,
    the one source of :func:`chain_bounds` and of the compiled period's chains."""
    slack = x_l - x_f - margin - (err_f_x + err_l_x)
    slack = xp.where(slack != slack, INF, slack)
    _, decel, broken = chain_link(xp, slack, v_f + err_f_v, xp.maximum(v_l - err_l_v, 0.0), a_ahead, promise, a_o)
    return decel, broken


def chain_bounds(x, v, promise, n_connected, human, err, prm: Params):
    """``(bounds (B, M), unsafe (B,))`` of a chain ``x, v (B, M)`` (``L1`` or ``L0`` first) whose states are known to
    ``err (B, M, 2)``, each link at its own worst corner (see the module docstring); ``+inf`` positions (no vehicle)
    leave the links ahead of them free."""
    b, m = x.shape
    in_chain = np.arange(m - 1)[None, :] < n_connected[:, None]
    a_o = prm.others_decel  # what any other vehicle may brake (a_x_d in the paper's world)
    promise = np.where(in_chain, promise, a_o)
    margin = np.where(human & in_chain, prm.p_m_human, prm.p_m)
    e = np.zeros((b, m, 2)) if err is None else err
    decel = [np.full(b, a_o)]
    unsafe = np.zeros(b, bool)
    a_ahead = decel[0]
    with np.errstate(all="ignore"):
        for i in range(m - 2, -1, -1):
            a_ahead, broken = link_at_corner(ARRAY, x[:, i], v[:, i], e[:, i, 0], e[:, i, 1], x[:, i + 1],
                                             v[:, i + 1], e[:, i + 1, 0], e[:, i + 1, 1], margin[:, i], a_ahead,
                                             promise[:, i], a_o)  # fmt: skip
            unsafe |= broken
            decel.insert(0, a_ahead)
    return np.column_stack(decel), unsafe


def own_lane_decel(s: Situation, prm: Params, informed, broken) -> np.ndarray:
    """``(B,)`` ``L0``'s worst-case deceleration: its own chain's bound where the variant uses chain information
    (``informed``) and no assumption broke (``broken``), else the others' maximum ``a_o_d``."""
    bounds, unsafe = chain_bounds(s.own_x, s.own_v, s.own_promise, s.own_n_connected,
                                  np.zeros(s.own_promise.shape, bool), s.err_own, prm)  # fmt: skip
    return np.where(informed & ~unsafe & ~broken, bounds[:, 0], prm.others_decel)


def carry_worst(x, v, decel, horizon: float):
    """A vehicle's state after ``horizon`` along its worst-case trajectory: constant acceleration ``-decel``
    (``decel`` may be negative: an aggressive F accelerates), stopping at rest (:func:`carry_worst_core`)."""
    with np.errstate(over="ignore"):  # (as _motion.advance)
        return carry_worst_core(ARRAY, x, v, np.asarray(decel, float), horizon)


def carry_worst_core(xp, x, v, decel, horizon):
    """Backend-generic :func:`carry_worst` (the compiled period carries ``L0`` with it, row by row)."""
    return advance_core(xp, x, v, -decel, horizon)


def carried_others(xp, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive, a_x_a, a_x_d, delay):
    """``(l1_x, l1_v, f_x, f_v)`` after the delay along their worst cases (the frame of a delayed decision,
    :func:`.stages.frame`): L1 braking at ``l1_decel``, F accelerating at ``a_x_a`` where it is taken for
    aggressive, else braking at ``a_x_d``; both stop at rest. Backend-generic (the compiled period, per row)."""
    l1_x, l1_v = carry_worst_core(xp, l1_x, l1_v, l1_decel, delay)
    f_x, f_v = carry_worst_core(xp, f_x, f_v, xp.where(f_aggressive, -a_x_a, a_x_d), delay)
    return l1_x, l1_v, f_x, f_v


def delay_periods(cfg, prm: Params) -> int:
    """The actuation delay of ``cfg`` (a ``ShieldConfig`` or ``SimConfig``) in control periods; a delay that is not
    a whole number of periods is refused."""
    d = round(cfg.actuation_delay_s / prm.dt)
    if abs(d * prm.dt - cfg.actuation_delay_s) > TIME_TOL_S:
        raise ValueError(f"{type(cfg).__name__}.actuation_delay_s={cfg.actuation_delay_s} must be a whole number of "
                         f"control periods (dt={prm.dt} s)")  # fmt: skip
    return d


def in_flight_checked(plan: EvasionPlan, s: Situation, own, delay: float, prm: Params) -> EvasionPlan:
    """``plan`` marked infeasible where the commands acting at the start (cruise, :meth:`~.command.InFlight.idle`)
    break a worst-case gap during the delay: to L1 and F while the ego is in the conflict zone, to L0 throughout."""
    tol = FEASIBILITY_TOL_M
    ex, evx = s.ego_x, s.ego_vx
    zero = np.zeros(len(s))
    y_max = lateral_max(ARRAY, s.ego_y, s.ego_vy, zero, s.ego_y + s.ego_vy * delay, delay)
    conflict = y_max > prm.y_safe + LATERAL_TOL_M
    gap_l = pair_min_gap(s.chain_x[:, 0] - ex - prm.p_m, evx, zero, s.chain_v[:, 0], -prm.others_decel + zero, delay)
    gap_f = pair_min_gap(ex - s.f_x - prm.p_m, s.f_v, prm.a_x_a + zero, evx, zero, delay)
    ok = ~conflict | ((gap_l >= -tol) & (gap_f >= -tol))
    if own is not None:
        has = np.isfinite(own[0])
        slack = np.where(has, own[0] - ex - prm.p_m, 0.0)
        ok &= ~has | (pair_min_gap(slack, evx, zero, np.where(has, own[1], 0.0), -own[2], delay) >= -0.5 * tol)
    return dataclasses.replace(plan, feasible=plan.feasible & ok)


def own_plan(plan: EvasionPlan, args, own, prm: Params) -> EvasionPlan:
    """``plan`` with the rows that have an own-lane leader replanned with it (:mod:`safelane.safety.own_lane`; its
    rows compiled where the kernels are, :func:`._fast_own.own_lane_rows`, the same bits)."""
    rows = np.flatnonzero(np.isfinite(own[0]))
    sub = tuple(np.broadcast_to(a, plan.feasible.shape)[rows] for a in args)
    own_r = tuple(np.broadcast_to(a, plan.feasible.shape)[rows] for a in own)
    kernel = own_kernel()
    core = own_lane_core if kernel is None else kernel.own_lane_rows
    with np.errstate(all="ignore"):
        margin = own_margin(prm)
        exists, parts = core(*sub, *own_r, prm.p_m, prm.p_m, margin, prm)
        piece = plan_from_core(ARRAY, rows.shape, (*sub, prm.p_m, prm.p_m), exists, parts, prm.p_m, prm.p_m, prm,
                               own=(*own_r, margin))  # fmt: skip
    return set_rows(plan, [(rows, piece)])


jitable(carry_worst_core, carried_others, behind_corner, ahead_corner, link_at_corner)
