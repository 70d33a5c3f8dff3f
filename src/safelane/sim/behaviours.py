"""Behaviour models of the target-lane vehicles (each small, documented and parameterised).

* **L(N+1)** (not connected): constant speed, then sudden braking at ``a_x_N+1_d`` from ``brake_start_s``
  until it stops — or any piecewise-constant profile inside ``[−a_x_d, a_x_a]``
  (:func:`safelane.sim.traffic.with_last_profile`), switching at any instant.
* **Connected L_i** (:func:`leader_accels`): its own driving task (hold the initial speed, or a traffic hook's
  wish) clipped to the promise ``[−a_m_d, a_m_a]``, kept while it leaves a safe distance against the vehicle
  ahead's *worst case* (its chain bound; ``a_x_d`` for ``L(N+1)``); otherwise the minimal braking that does —
  beyond the promise only as far as the chain analysis allows (an *expected* violation). So no leader ever
  brakes harder than the bound the ego's analysis gave it. *Unexpected* violation: with probability ``p_v`` per
  period, independently per connected vehicle, it brakes at ``U[z_i, a_x_N+1_d]`` for that period (paper §4.2).
* **Follower F** (see :func:`follower_accel`): collaborative or aggressive, always a *responsible* follower of
  L1 and — collaborative from the ego's signal at ``t = 0``, aggressive once the lane change completes — of
  the ego.

A responsible follower picks the largest acceleration ``a <= a_wanted`` such that after one period at ``a`` it
can still keep its margin by braking at ``a_x_d`` while the vehicle ahead brakes at its worst case
(RSS's proper response with a one-period response time); if none exists it brakes at ``a_x_d``.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, FEASIBILITY_TOL_M
from ..safety.chain import min_follow_decel
from ..safety.evasion import fast_kernel
from ..safety.responsible import ROOT_EPS_MPS2, responsible_accel, responsible_bound, responsible_ok

#: :func:`leader_accels` runs the compiled kernel (:mod:`._fast_traffic`) from this many ``(B, K)`` elements on.
FAST_MIN_ELEMENTS = 64


def traffic_kernel():
    """The compiled traffic kernel's module :mod:`._fast_traffic`, or ``None`` (numba missing, or
    ``SAFELANE_NO_NUMBA=1``: :func:`safelane.safety.evasion.fast_kernel`)."""
    if fast_kernel() is None:
        return None
    from . import _fast_traffic

    return _fast_traffic


def leader_roles(valid, connected, n_connected):
    """Per-slot roles for :func:`leader_accels`, constant over a run: ``(is_last, acts)``, both ``(B, K)``
    column-major — slot ``i`` is ``L(N+1)``, or a connected ``L_i`` acting on its own (slot 0, F, is neither)."""
    slots = np.arange(valid.shape[1])[None, :]
    is_last = np.asfortranarray(slots == n_connected[:, None] + 1)
    acts = np.asfortranarray(connected & valid & (slots >= 1) & (slots <= n_connected[:, None]) & ~is_last)
    return is_last, acts


def leader_accels(x, v, margin, roles, bounds, task, a_last, decel_last, violating, violate_pick, prm: Params):
    """Accelerations of L1..L(N+1) for this period, ``(B, K)`` with index 0 (F) left at 0.

    A connected ``L_i`` keeps its own ``task`` (already inside its promise) while that keeps a safe distance
    against the vehicle ahead's *worst case* — its chain bound ``bounds[:, i+1]`` (``a_x_d`` for ``L(N+1)``) —
    with ``L_i`` itself able to brake at no more than its own bound ``bounds[:, i]`` afterwards; otherwise it
    brakes minimally for that (:func:`responsible_bound` with ``brake = bounds[:, i]``, checked exactly by
    :func:`responsible_ok`; where the closed form is not confirmed it brakes at its bound, always safe). So a
    leader never brakes harder than its current bound, and its bound never grows: the worst case the ego's held
    plan assumed for ``L1`` stays a worst case (the consistency invariant, docs/simulator.md). From
    :data:`FAST_MIN_ELEMENTS` elements on it runs the compiled kernel (:mod:`._fast_traffic`) where numba imports and
    ``SAFELANE_NO_NUMBA`` is not ``1``: the same bits as the NumPy path below, the reference.

    Args:
        x, v: ``(B, K)`` current positions and speeds. ``margin``: ``(B, K)`` each vehicle's margin to the one
            ahead (``p_m`` or ``p_m_human``). ``roles``: from :func:`leader_roles`.
        bounds: ``(B, K)`` each vehicle's worst-case deceleration from the chain analysis on the current states
            (``a_x_d`` for ``L(N+1)`` and anything not connected).
        task: ``(B, K)`` the connected leaders' own wanted accelerations, inside their promises.
        a_last: ``(B,)`` ``L(N+1)``'s acceleration at the start of the period (its profile).
        decel_last: ``(B,)`` ``a_x_N+1_d`` (the top of an unexpected violation's range).
        violating: ``(B, K)`` an unexpected violation this period, or ``None`` for none anywhere; then the vehicle
            brakes at ``U[z_i, a_x_N+1_d]`` (``violate_pick`` the uniforms), whatever its bound.
    """
    if np.size(x) >= FAST_MIN_ELEMENTS and (kernel := traffic_kernel()) is not None:
        return kernel.leader_accels(x, v, margin, roles, bounds, task, a_last, decel_last, violating, violate_pick, prm)
    bsz, k = x.shape
    is_last, acts = roles
    acc = np.zeros((bsz, k))
    if k > 2:
        # Followers are slots 1..K-2 (connected leaders never sit in the last slot), each behind the next slot.
        slack = x[:, 2:] - x[:, 1:-1] - margin[:, 1:-1]
        v_f, v_l, d, own = v[:, 1:-1], v[:, 2:], bounds[:, 2:], bounds[:, 1:-1]
        with np.errstate(all="ignore"):
            bound = responsible_bound(slack, v_f, v_l, d, prm, brake=own) - ROOT_EPS_MPS2
            want = np.minimum(task[:, 1:-1], bound)
            # The closed form is exact where the leader's own bound is at least the vehicle ahead's (then the gap
            # is convex after the period: tested); elsewhere it is confirmed by the exact check.
            ok = np.ones(want.shape, bool)
            soft = own < d
            if soft.any():
                ok[soft] = responsible_ok(want[soft], slack[soft], v_f[soft], v_l[soft], d[soft], prm,
                                          brake=own[soft], tol=FEASIBILITY_TOL_M)  # fmt: skip
            a_conn = np.maximum(np.where(ok, want, -own), -own)
            if violating is not None:
                z = np.minimum(min_follow_decel(ARRAY, slack, v_f, v_l, d), prm.others_decel)
                lo, hi = np.minimum(z, decel_last[:, None]), np.maximum(z, decel_last[:, None])
                a_conn = np.where(violating[:, 1:-1], -(lo + violate_pick[:, 1:-1] * (hi - lo)), a_conn)
        acc[:, 1:-1] = np.where(acts[:, 1:-1], a_conn, 0.0)
    acc = np.where(is_last, a_last[:, None], acc)
    return np.asfortranarray(acc)


def reactive_leader_accels(x, v, margin, roles, task, a_last, decel_last, violating, violate_pick, prm: Params):
    """The *reactive* leader rule (``SimConfig.leader_rule = "reactive"``, the paper-faithful preset's): a connected
    ``L_i`` keeps its task unless the vehicle ahead's *current* braking needs more, then takes the minimal safe
    deceleration of Eqs. 2–3 against that (an expected violation); decisions resolved front to back within a period
    (perfect V2X coordination). Physically natural — leaders brake only when the traffic ahead does — and what
    reproduces the paper's Table 1, but **outside the guarantee's assumptions**: a leader may later brake harder
    than the bound the chain analysis gave it (when the vehicle ahead brakes, eases off, then brakes harder), which
    can void an ego's held plan (docs/simulator.md, "Leader rules"). Same arguments as :func:`leader_accels` but
    no bounds. The loop runs over the chain (each link reacts to the one ahead), vectorized over the batch.
    """
    bsz, k = x.shape
    is_last, acts = roles
    mixed = is_last.any(0) | ~acts.all(0)  # per slot: not every row an acting connected leader (then a mask)
    acc = np.zeros((bsz, k), order="F")  # column-major: filled vehicle by vehicle
    slack = x[:, 1:] - x[:, :-1] - margin[:, :-1]
    with np.errstate(all="ignore"):
        for i in range(k - 1, 0, -1):  # front to back: each link reacts to the one ahead (a scan over vehicles)
            if i + 1 < k:
                ahead_decel = np.maximum(-acc[:, i + 1], 0.0)
                z = np.minimum(
                    min_follow_decel(ARRAY, slack[:, i], v[:, i], v[:, i + 1], ahead_decel), prm.others_decel
                )
            else:
                z = np.zeros(bsz)
            a_conn = np.minimum(task[:, i], -z)
            if violating is not None:
                lo, hi = np.minimum(z, decel_last), np.maximum(z, decel_last)
                a_conn = np.where(violating[:, i], -(lo + violate_pick[:, i] * (hi - lo)), a_conn)
            acc[:, i] = np.where(is_last[:, i], a_last, np.where(acts[:, i], a_conn, 0.0)) if mixed[i] else a_conn
    return acc


def leader_task(v, v_desired, promise_decel, promise_accel, wanted=None):
    """Each connected leader's own driving task, inside its promise ``[−a_m_d, a_m_a]``: ``wanted`` (a traffic
    hook's wish) or, by default, holding its initial speed (a P law)."""
    if wanted is None:
        wanted = 0.5 * (v_desired - v)
    return np.minimum(np.maximum(wanted, -promise_decel), promise_accel)


def follower_accel(
    f_x,
    f_v,
    l1_x,
    l1_v,
    ego_x,
    ego_vx,
    aggressive,
    completed,
    gap0,
    prm: Params,
    open_decel: float,
    open_gap_m: float,
    wanted=None,
    ignores_ego: bool = False,
):
    """Follower acceleration for this period.

    * collaborative: once the ego signals (``t = 0``) it opens the gap a little — brakes at ``open_decel``
      until the gap to the ego has grown by ``open_gap_m``, then matches the ego's speed — and follows the
      ego responsibly (brakes as needed, up to ``a_x_d``) whenever the ego is ahead of it;
    * aggressive: until the lane change completes, closes the gap to L1 (PD law on the gap to ``p_m``,
      up to ``a_x_a``), ignoring the ego; afterwards it follows the ego responsibly.
    Both always follow L1 responsibly (L1's worst case, and F's own braking: the others' maximum ``a_o_d``).
    ``wanted``: a traffic hook's wish
    (:class:`safelane.sim.traffic.TrafficHooks`) replacing both nominal laws, inside ``[−a_x_d, a_x_a]``; the
    responsible filters still apply. ``ignores_ego`` (outside the assumptions): F never follows the ego. From
    :data:`FAST_MIN_ELEMENTS` scenarios on it runs the compiled kernel (:mod:`._fast_traffic`), the same bits.
    """
    if np.size(f_x) >= FAST_MIN_ELEMENTS and (kernel := traffic_kernel()) is not None:
        return kernel.follower_accel(f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, completed, gap0, prm, open_decel,
                                     open_gap_m, wanted, ignores_ego)  # fmt: skip
    gap_ego = ego_x - f_x
    collab_nominal = np.where(gap_ego < gap0 + open_gap_m, -open_decel, np.clip(ego_vx - f_v, -open_decel, open_decel))
    gap_l1 = l1_x - f_x
    # F is one of the others: it brakes up to a_o = a_o_d and, as RSS's rear vehicle, takes the vehicle ahead (L1 or
    # the ego) to brake up to a_o as well (a_x_d, and the paper's F, where a_o_d is not set).
    a_o = prm.others_decel
    aggr_nominal = np.clip(0.5 * (gap_l1 - prm.p_m - 1.0) + 1.5 * (l1_v - f_v), -a_o, prm.a_x_a)
    if wanted is None:
        wanted = np.where(aggressive, aggr_nominal, collab_nominal)
    a = responsible_accel(wanted, gap_l1 - prm.p_m, f_v, l1_v, a_o, prm, brake=a_o)
    follows_ego = (gap_ego > 0.0) & (~aggressive | completed) & (not ignores_ego)
    a_ego = responsible_accel(a, gap_ego - prm.p_m, f_v, ego_vx, a_o, prm, brake=a_o)
    return np.where(follows_ego, a_ego, a)
