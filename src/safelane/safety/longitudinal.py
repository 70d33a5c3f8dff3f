"""Longitudinal evasion behind the worst-case braking leader ``L1`` (paper Eqs. 6–8, Figure 3).

Over the lateral evasion time ``[0, T]`` (``T = t_y_f``) the ego must keep ``p_1(t) − p(t) >= p_m`` while
staying as far ahead as possible (the follower is behind it). The profile has three phases: accelerate
at ``a_x_a`` on ``[0, t_x1]``; brake at ``a_x_d`` until either its speed meets ``L1``'s while ``L1`` still
moves (then it *follows* ``L1``, braking at ``a_x_1_d`` at a constant gap) or it stops; ``t_x2`` ends the
braking phase. The gap is concave while the ego accelerates and non-increasing while it brakes faster
than ``L1``, so its minimum over ``[0, T]`` is at ``0``, ``t_x1``, ``min(t_x2, T)`` or ``T`` — all checked.

``t_x1`` is the largest switch time whose minimum gap is ``>= 0``; the minimum gap is non-increasing in
``t_x1``, so this is well defined. The candidates are the closed forms of Eq. 7 — one per place the
binding gap can be (Figure 3):

* case (a), still braking at ``T``: ``t_x1 = T − sqrt(T² − (a_x_d T² + 2R)/(a_x_a + a_x_d))`` with
  ``R = p_1(T) − p_m − p − v T`` (the paper's first case, correct);
* case (b), ego stops after ``L1`` has: ``t_x1 = −v/a_x_a + sqrt((v/a_x_a)² − (v² + 2 a_x_d (p + p_m −
  p_1^stop))/((a_x_a + a_x_d) a_x_a))`` (the paper's second case, correct);
* cases (c)/(d), speed matched with moving ``L1``: ``t_x1 = (−w + sqrt(w² − 2 k C_2))/k``, ``w = v − v_1``,
  ``k = a_x_a + a_x_1_d`` (the paper prints this formula twice; it is the same for both cases because the gap
  is frozen from ``t_x2`` on whether or not ``L1`` stops before ``T``).

The paper selects the case by conditions that involve the unknown ``t_x1`` (and mixes ``t_y_f`` with
``t_x1``); here each candidate is clipped to ``[0, T]``, its minimum gap evaluated exactly, and the largest
feasible one kept — which by monotonicity is the exact optimum. ``T`` itself (accelerate throughout) is a
candidate too, and full braking from ``t = 0`` (``t_x1 = 0``) failing means no evasion exists.

**``L1`` braking harder than the ego** (``a1 > a_x_d``: the others' maximum ``a_o_d`` above the ego's committed
braking). The ego cannot follow ``L1`` (that would mean braking at ``a1``), so the profile is accelerate → brake at
``a_x_d`` to rest (:func:`profile`: ``match`` needs ``a1 <= a_x_d``). The gap is then concave while both move (its
second derivative is ``−a_x_a − a1`` while the ego accelerates, ``a_x_d − a1 < 0`` while it brakes) and
non-increasing once ``L1`` has stopped, so its minimum is still at ``0``, ``u``, ``min(t2, T)`` or ``T``. At the
largest feasible ``u`` the gap binds at ``T`` with the ego still braking (case a's closed form, which reads ``L1``
only through ``p_1(T)``) or at the ego's stop after ``L1``'s (case b's): it cannot bind at the ego's stop while
``L1`` still moves (the gap grows there, at ``L1``'s speed) nor at ``u`` alone (concave there). So the candidates
``u_a``, ``u_b`` and ``T`` contain the optimum and the selection stays exact; ``u_c`` is an extra, harmless candidate.
The profile is still the position-maximal one at every instant: a motion ahead of it at some ``t0 > u`` is ahead
from ``t0`` on (it brakes no harder), hence past ``L1``'s margin at the binding instant if that is later, or at
``t0`` itself if not (then both have stopped: the margin no longer moves).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from ._backend import FEASIBILITY_TOL_M, INF, jitable
from ._checks import check_params, finish, prepare
from .chain import braked_position, decel_cap

__all__ = ["FEASIBILITY_TOL_M"]  # defined in _backend (chain.py needs it too); re-exported here as before


def profile(xp, u, p, v, p1, v1, a1, prm: Params, l1_stop=None):
    """Switch state of the profile with acceleration phase ``[0, u]``: ``(V, t2, match)``.

    ``match``: the braking ego reaches ``L1``'s speed while ``L1`` moves and follows it from ``t2`` on — possible only
    where ``L1`` brakes no harder than the ego's committed ``a_x_d`` (``a1 <= a_x_d``); otherwise the ego brakes at
    ``a_x_d`` to rest (``t2`` its stop).

    ``l1_stop`` is ``L1``'s stop time ``xp.stop_time(v1, a1)``, computed here unless given.
    """
    a_d = prm.a_x_d
    V = v + prm.a_x_a * u
    if l1_stop is None:
        l1_stop = xp.stop_time(v1, a1)
    rel = V - xp.maximum(v1 - a1 * u, 0.0)  # ego minus L1 speed at u
    m = a_d - a1
    t_match = u + xp.where(rel == 0.0, 0.0, xp.div(rel, m, INF))
    # Following L1 means braking at a1: only within the ego's committed a_x_d (m >= 0). An L1 braking harder
    # (a1 > a_x_d: the others' maximum beyond the ego's) is never followed; the ego brakes at a_x_d to rest.
    match = (rel >= 0.0) & (t_match <= l1_stop) & (m >= 0.0)
    t2 = xp.where(match, t_match, u + V / a_d)
    return V, t2, match


def ego_position(xp, t, p, v, u, V, t2, match, p1, v1, a1, prm: Params, l1_stop=None):
    """Ego position on the evasion profile at ``t`` (exact; valid for any ``t >= 0``); ``l1_stop`` as in
    :func:`profile`."""
    ta = xp.minimum(t, u)
    pos = p + v * ta + 0.5 * prm.a_x_a * ta * ta
    tb = xp.maximum(xp.minimum(t, t2) - u, 0.0)
    pos = pos + V * tb - 0.5 * prm.a_x_d * tb * tb
    t_late = xp.maximum(t, t2)
    if l1_stop is None:
        l1_stop = xp.stop_time(v1, a1)
    follow = braked_position(xp, p1, v1, a1, t_late, l1_stop) - braked_position(xp, p1, v1, a1, t2, l1_stop)
    return pos + xp.where(match, follow, 0.0)


def ego_speed(xp, t, v, u, V, t2, match, v1, a1, prm: Params):
    """Ego speed on the evasion profile at ``t``."""
    ta = xp.minimum(t, u)
    tb = xp.maximum(xp.minimum(t, t2) - u, 0.0)
    own = v + prm.a_x_a * ta - prm.a_x_d * tb
    l1_speed = xp.maximum(v1 - a1 * t, 0.0)
    return xp.where(match & (t > t2), l1_speed, xp.maximum(own, 0.0))


def leader_gap_min(xp, u, T, d0, p, v, p1, v1, a1, margin, prm: Params, l1_stop=None, l1_at_T=None):
    """Minimum over ``[0, T]`` of ``p_1(t) − p(t) − margin`` for switch time ``u <= T`` (exact).

    ``l1_stop`` is as in :func:`profile` and ``l1_at_T`` is ``L1``'s position at ``T``; both are computed here
    unless given. The gap is checked at ``0`` (``d0``), ``u``, ``min(t2, T)`` and ``T``. This is
    :func:`ego_position` written out for those times, with the same arithmetic, to spare the hot path its
    repeated terms: all three are ``>= u`` (so the acceleration phase is complete), and the following phase,
    which starts at ``t2``, has contributed nothing yet at ``u`` or at ``min(t2, T)``.
    """
    if l1_stop is None:
        l1_stop = xp.stop_time(v1, a1)
    if l1_at_T is None:
        l1_at_T = braked_position(xp, p1, v1, a1, T, l1_stop)
    V, t2, match = profile(xp, u, p, v, p1, v1, a1, prm, l1_stop)
    at_u = p + v * u + 0.5 * prm.a_x_a * u * u

    def braking(t):
        tb = xp.maximum(xp.minimum(t, t2) - u, 0.0)
        return at_u + V * tb - 0.5 * prm.a_x_d * tb * tb

    t_b = xp.minimum(t2, T)
    l1_at_t2 = braked_position(xp, p1, v1, a1, t2, l1_stop)
    follow = braked_position(xp, p1, v1, a1, xp.maximum(T, t2), l1_stop) - l1_at_t2
    ego_at_T = braking(T) + xp.where(match, follow, 0.0)
    gmin = xp.minimum(d0, (braked_position(xp, p1, v1, a1, u, l1_stop) - at_u) - margin)
    gmin = xp.minimum(gmin, (braked_position(xp, p1, v1, a1, t_b, l1_stop) - braking(t_b)) - margin)
    return xp.minimum(gmin, (l1_at_T - ego_at_T) - margin)


def longitudinal_core(xp, p, v, p1, v1, a1, T, margin, prm: Params, tol: float = FEASIBILITY_TOL_M):
    """Backend-generic core. Returns ``(feasible, u, V, t2, match, gap_min)``."""
    a_a, a_d = prm.a_x_a, prm.a_x_d
    d0 = p1 - p - margin
    s = a_a + a_d
    l1_stop = xp.stop_time(v1, a1)  # hoisted with l1_at_T: every gap evaluation below reuses them
    l1_at_T = braked_position(xp, p1, v1, a1, T, l1_stop)
    big_r = l1_at_T - margin - p - v * T
    u_a = T - xp.sqrt(T * T - (a_d * T * T + 2.0 * big_r) / s)
    p1_stop = p1 + xp.stop_dist(v1, a1)
    u_b = -v / a_a + xp.sqrt((v / a_a) * (v / a_a) - (v * v + 2.0 * a_d * (p + margin - p1_stop)) / (s * a_a))
    w = v - v1
    k = a_a + a1
    u_c = (-w + xp.sqrt(w * w - k * (w * w - 2.0 * (a_d - a1) * d0) / s)) / k
    best = 0.0 * T
    best_gap = leader_gap_min(xp, best, T, d0, p, v, p1, v1, a1, margin, prm, l1_stop, l1_at_T)
    feasible = best_gap >= -tol
    # The largest feasible candidate clipped to [0, T] (a later one on a tie: the same gap).
    for c in (u_a, u_b, u_c, T):
        cand = xp.clip(c, 0.0, T)
        g = leader_gap_min(xp, cand, T, d0, p, v, p1, v1, a1, margin, prm, l1_stop, l1_at_T)
        better = (g >= -tol) & (cand >= best)
        best = xp.where(better, cand, best)
        best_gap = xp.where(better, g, best_gap)
    V, t2, match = profile(xp, best, p, v, p1, v1, a1, prm, l1_stop)
    return feasible, best, V, t2, match, best_gap


@dataclass(frozen=True)
class LongitudinalEvasion:
    """Result of :func:`longitudinal_evasion` (arrays of the batch shape).

    ``case``: 0 accelerate throughout (``t_x1 = T``); 1–4 the four cases of the paper's Figure 3 —
    1 still braking at ``T``, 2 stopped before ``T`` (``L1`` stopped first), 3 following ``L1`` which still
    moves at ``T``, 4 following ``L1`` to a stop before ``T``; −1 infeasible.
    """

    feasible: np.ndarray
    t_x1: np.ndarray
    t_x2: np.ndarray
    case: np.ndarray
    min_gap: np.ndarray


def longitudinal_evasion(ego_px, ego_vx, l1_p, l1_v, l1_decel, t_y_f, params: Params):
    """Optimal accelerate–brake–follow evasion profile behind ``L1`` on ``[0, t_y_f]`` (Eqs. 6–8).

    Args (all broadcast): ego position/speed, ``L1`` position/speed and worst-case deceleration
    (``[0, max(a_x_d, a_o_d)]``: ``L1`` may brake harder than the ego commits to), evasion horizon ``t_y_f >= 0``.

    Returns :class:`LongitudinalEvasion`; ``min_gap`` is the smallest ``p_1 − p`` over ``[0, t_y_f]``.
    """
    check_params(params)
    xp, a, shape = prepare(
        {"ego_px": ego_px, "ego_vx": ego_vx, "l1_p": l1_p, "l1_v": l1_v, "l1_decel": l1_decel, "t_y_f": t_y_f},
        nonneg=("ego_vx", "l1_v", "l1_decel", "t_y_f"),
        upper={"l1_decel": decel_cap(params)},
    )
    p, v, p1, v1, a1, T = (a[k] for k in ("ego_px", "ego_vx", "l1_p", "l1_v", "l1_decel", "t_y_f"))
    with np.errstate(all="ignore"):
        feasible, u, _V, t2, match, gap = longitudinal_core(xp, p, v, p1, v1, a1, T, params.p_m, params)
        l1_stop = xp.stop_time(v1, a1)
        case = xp.where(
            u >= T,
            0,
            xp.where(t2 >= T, 1, xp.where(match, xp.where(l1_stop >= T, 3, 4), 2)),
        )
        case = xp.where(feasible, case, -1)
    return LongitudinalEvasion(
        feasible=finish(xp, shape, feasible, np.bool_),
        t_x1=finish(xp, shape, u),
        t_x2=finish(xp, shape, xp.minimum(t2, T)),
        case=finish(xp, shape, case, np.int8),
        min_gap=finish(xp, shape, gap + params.p_m),
    )


# The closed forms compiled into the kernels (safety/_compile.py): the same functions, evaluated row by row.
jitable(profile, ego_position, ego_speed, leader_gap_min, longitudinal_core)
