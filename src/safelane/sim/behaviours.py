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

**One source.** Each rule is one backend-generic closed form per row (first argument the backend ``xp`` of
:mod:`safelane.safety._backend`, marked ``jitable`` at the end of the module): :func:`last_accel` (``L(N+1)``'s
default profile), :func:`hold_speed` and
:func:`task_core` (a leader's task), :func:`leader_want`, :func:`leader_needs_check`, :func:`leader_confirmed` and
:func:`leader_keep` (the worst-case rule), :func:`link_decel` and :func:`violation_accel` (an unexpected violation;
with :func:`reactive_core`, the reactive rule), :func:`follower_wish_core`, :func:`follow_core` and
:func:`follows_ego` (F); the chain scan's link is :func:`safelane.safety.chain.chain_link`. The functions below
evaluate them on NumPy arrays (``ARRAY``); the compiled kernels (:mod:`._fast_traffic`, :mod:`._fast_loop`) compile
the very same functions on ``SCALAR`` and keep only loops, indexing and the branches that skip what a mask or a
``where`` here discards (the exact check where :func:`leader_needs_check` is false, the rule of a leader that
violates, F's follow of the ego where :func:`follows_ego` is false): the same bits (``tests/test_fast_traffic.py``).
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..planners.adversarial import wave_level  # noqa: F401  (the square wave's one home; used by WaveHooks)
from ..safety._backend import ARRAY, FEASIBILITY_TOL_M, INF, jitable
from ..safety.chain import min_follow_decel, propagate_chain
from ..safety.evasion import fast_kernel
from ..safety.responsible import ROOT_EPS_MPS2, responsible_accel_core, responsible_bound_core, responsible_ok_core
from ..tolerances import TIME_TOL_S

#: :func:`leader_accels` runs the compiled kernel (:mod:`._fast_traffic`) from this many ``(B, K)`` elements on.
FAST_MIN_ELEMENTS = 64


def traffic_kernel():
    """The compiled traffic kernel's module :mod:`._fast_traffic`, or ``None`` (numba missing, or
    ``SAFELANE_NO_NUMBA=1``: :func:`safelane.safety.evasion.fast_kernel`)."""
    if fast_kernel() is None:
        return None
    from . import _fast_traffic

    return _fast_traffic


def last_accel(xp, t, brake_start, decel_last):
    """``L(N+1)``'s default profile at time ``t``: constant speed, then braking at ``decel_last`` (``a_x_N+1_d``) from
    ``brake_start`` on (a start within 1 ns after ``t`` counts: round-off in the period count)."""
    return xp.where(t + TIME_TOL_S >= brake_start, -decel_last, 0.0)


def leader_roles(valid, connected, n_connected):
    """Per-slot roles for :func:`leader_accels`, constant over a run: ``(is_last, acts)``, both ``(B, K)``
    column-major — slot ``i`` is ``L(N+1)``, or a connected ``L_i`` acting on its own (slot 0, F, is neither)."""
    slots = np.arange(valid.shape[1])[None, :]
    is_last = np.asfortranarray(slots == n_connected[:, None] + 1)
    acts = np.asfortranarray(connected & valid & (slots >= 1) & (slots <= n_connected[:, None]) & ~is_last)
    return is_last, acts


def lane_bounds(x, v, promise, margin, prm: Params):
    """The chain analysis on true states: ``(bounds (B, K), unsafe (B,))`` of a lane laid out as the target lane's
    ``x, v`` (slot 0 the follower, ``F``; the chain from slot 1, its non-connected head last), ``bounds[:, i]`` the
    worst-case deceleration of slot ``i`` (the others' maximum ``a_o_d`` for slot 0, the head and anything not
    connected). ``promise``, ``margin``: ``(K − 2, B)`` vehicle-major, one per link from slot 1 on (``a_o_d`` for a
    link that is not connected). From :data:`FAST_MIN_ELEMENTS` rows on the compiled scan, the same bits."""
    if len(x) >= FAST_MIN_ELEMENTS and (kernel := traffic_kernel()) is not None:
        return kernel.chain_bounds(x, v, promise, margin, prm)
    n_links = x.shape[1] - 2
    with np.errstate(all="ignore"):  # inputs were checked with the batch: the scan alone, unchecked
        decel, _, unsafe = propagate_chain(ARRAY, x.T[1:], v.T[1:], promise, margin, prm, n_links)
    others = np.full(len(x), prm.others_decel)  # slot 0: one of the others
    bounds = np.column_stack([others, *(np.broadcast_to(d, (len(x),)) for d in decel)])
    return bounds, np.broadcast_to(np.asarray(unsafe, bool), (len(x),))


def leader_want(xp, slack, v_f, v_l, d, own, task, dt):
    """A connected leader's wish: its ``task``, capped by the largest acceleration that keeps it responsible behind
    the vehicle ahead braking at ``d`` with its own bound ``own`` as its braking
    (:func:`~safelane.safety.responsible.responsible_bound_core`, ``ROOT_EPS_MPS2`` on the safe side)."""
    return xp.minimum(task, responsible_bound_core(xp, slack, v_f, v_l, d, own, dt) - ROOT_EPS_MPS2)


def leader_needs_check(xp, own, d):
    """Where :func:`leader_want`'s closed form is not exact, so :func:`leader_confirmed` must confirm it: the leader's
    own bound softer than the one ahead (elsewhere the gap is convex after the period: tested)."""
    return own < d


def leader_confirmed(xp, want, slack, v_f, v_l, d, own, dt):
    """The exact check of :func:`leader_want` (:func:`~safelane.safety.responsible.responsible_ok_core` with brake
    ``own``, gaps within ``FEASIBILITY_TOL_M`` of the margin kept)."""
    return responsible_ok_core(xp, want, slack, v_f, v_l, d, own, dt, FEASIBILITY_TOL_M, FEASIBILITY_TOL_M)


def leader_keep(xp, want, ok, own):
    """The leader's acceleration: its wish where confirmed (``ok``), else its bound ``-own`` (always safe); never
    harder than ``-own``."""
    return xp.maximum(xp.where(ok, want, -own), -own)


def link_decel(xp, slack, v_f, v_l, a_l, a_o):
    """The least deceleration that keeps a link's follower clear of a vehicle ahead braking at ``a_l`` (Eq. 3,
    :func:`~safelane.safety.chain.min_follow_decel`), never beyond the others' maximum ``a_o``."""
    return xp.minimum(min_follow_decel(xp, slack, v_f, v_l, a_l), a_o)


def violation_accel(xp, z, decel_last, pick):
    """An unexpected violation: braking at ``U[z, a_x_N+1_d]`` (``pick`` the uniform draw; paper §4.2)."""
    lo, hi = xp.minimum(z, decel_last), xp.maximum(z, decel_last)
    return -(lo + pick * (hi - lo))


def reactive_core(xp, task, z):
    """The reactive rule's leader: its task, or the minimal safe deceleration ``z`` against the vehicle ahead's
    current braking where that needs more."""
    return xp.minimum(task, -z)


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
            want = leader_want(ARRAY, slack, v_f, v_l, d, own, task[:, 1:-1], prm.dt)
            ok = np.ones(want.shape, bool)
            soft = leader_needs_check(ARRAY, own, d)
            if soft.any():
                ok[soft] = leader_confirmed(ARRAY, want[soft], slack[soft], v_f[soft], v_l[soft], d[soft], own[soft],
                                            prm.dt)  # fmt: skip
            a_conn = leader_keep(ARRAY, want, ok, own)
            if violating is not None:
                z = link_decel(ARRAY, slack, v_f, v_l, d, prm.others_decel)
                a_conn = np.where(violating[:, 1:-1], violation_accel(ARRAY, z, decel_last[:, None],
                                                                      violate_pick[:, 1:-1]), a_conn)  # fmt: skip
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
                z = link_decel(ARRAY, slack[:, i], v[:, i], v[:, i + 1], ahead_decel, prm.others_decel)
            else:
                z = np.zeros(bsz)
            a_conn = reactive_core(ARRAY, task[:, i], z)
            if violating is not None:
                a_conn = np.where(violating[:, i], violation_accel(ARRAY, z, decel_last, violate_pick[:, i]), a_conn)
            acc[:, i] = np.where(is_last[:, i], a_last, np.where(acts[:, i], a_conn, 0.0)) if mixed[i] else a_conn
    return acc


def hold_speed(xp, v, v_desired):
    """A connected leader's default wish: holding its initial speed ``v_desired`` (a P law)."""
    return 0.5 * (v_desired - v)


def task_core(xp, wanted, promise_decel, promise_accel):
    """A connected leader's task: its wish inside its promise ``[−a_m_d, a_m_a]``."""
    return xp.minimum(xp.maximum(wanted, -promise_decel), promise_accel)


def leader_task(v, v_desired, promise_decel, promise_accel, wanted=None):
    """Each connected leader's own driving task, inside its promise ``[−a_m_d, a_m_a]``: ``wanted`` (a traffic
    hook's wish) or, by default, holding its initial speed (:func:`hold_speed`)."""
    if wanted is None:
        wanted = hold_speed(ARRAY, v, v_desired)
    return task_core(ARRAY, wanted, promise_decel, promise_accel)


def follower_wish_core(xp, f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, gap0, p_m, a_x_a, a_o, open_decel,
                       open_gap_m):  # fmt: skip
    """F's nominal wish (:func:`follower_accel`'s two laws): collaborative, brake at ``open_decel`` until the gap to
    the ego has grown by ``open_gap_m``, then match the ego's speed; aggressive, close on L1 (a PD law on the gap to
    ``p_m``, inside ``[−a_o, a_x_a]``)."""
    collab = xp.where(ego_x - f_x < gap0 + open_gap_m, -open_decel, xp.clip(ego_vx - f_v, -open_decel, open_decel))
    aggr = xp.clip(0.5 * (l1_x - f_x - p_m - 1.0) + 1.5 * (l1_v - f_v), -a_o, a_x_a)
    return xp.where(aggressive, aggr, collab)


def follow_core(xp, a_wanted, slack, v_f, v_l, a_o, dt):
    """F's responsible filter behind one vehicle: the vehicle ahead and F itself braking up to the others' maximum
    ``a_o`` (:func:`~safelane.safety.responsible.responsible_accel_core`)."""
    return responsible_accel_core(xp, a_wanted, responsible_bound_core(xp, slack, v_f, v_l, a_o, a_o, dt), a_o)


def follows_ego(xp, gap_ego, aggressive, completed, ignores_ego):
    """Whether F follows the ego as well as L1: the ego ahead of F, F collaborative or the lane change completed,
    and F not ignoring the ego."""
    return (gap_ego > 0.0) & xp.where(aggressive, completed, True) & xp.where(ignores_ego, False, True)


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
    # F is one of the others: it brakes up to a_o = a_o_d and, as RSS's rear vehicle, takes the vehicle ahead (L1 or
    # the ego) to brake up to a_o as well (a_x_d, and the paper's F, where a_o_d is not set).
    a_o, p_m, dt = prm.others_decel, prm.p_m, prm.dt
    with np.errstate(all="ignore"):
        if wanted is None:
            wanted = follower_wish_core(ARRAY, f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, gap0, p_m, prm.a_x_a,
                                        a_o, open_decel, open_gap_m)  # fmt: skip
        a = follow_core(ARRAY, wanted, l1_x - f_x - p_m, f_v, l1_v, a_o, dt)
        a_ego = follow_core(ARRAY, a, ego_x - f_x - p_m, f_v, ego_vx, a_o, dt)
        return np.where(follows_ego(ARRAY, ego_x - f_x, aggressive, completed, ignores_ego), a_ego, a)


def wave_wish(xp, level, low, span):
    """A wish at ``level`` (in ``[0, 1]``) of the range ``[low, low + span]``. Backend-generic."""
    return low + level * span


def gap_ratio(xp, valid, x_behind, x_ahead, margin):
    """A consecutive target-lane pair's gap over its margin where the pair is ``valid`` (``inf`` elsewhere): the
    falsifier's sample of the lane gaps at the start of each period (:class:`~.traffic.WaveHooks`). Backend-generic."""
    return xp.where(valid, (x_ahead - x_behind) / margin, INF)


# The closed forms compiled into the kernels (safety/_compile.py, through _fast_traffic and _fast_loop): the same
# functions, evaluated row by row.
jitable(
    last_accel, leader_want, leader_needs_check, leader_confirmed, leader_keep, link_decel, violation_accel,
    reactive_core, hold_speed, task_core, follower_wish_core, follow_core, follows_ego, wave_wish,
    gap_ratio,
)  # fmt: skip
