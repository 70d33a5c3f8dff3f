"""The evasion check with traffic in the ego's own lane: ``L0`` ahead of the ego in its original lane (real_roads.md).

The paper's evasion returns the ego to an *empty* original lane: it accelerates at ``a_x_a`` to stay ahead of ``F``,
brakes behind ``L1``, and after ``t_y_f`` cruises. With ``L0`` (the nearest vehicle ahead of the ego in its original
lane, braking at its worst-case deceleration ``a_0`` — ``a_x_d`` if it is not connected, else its own chain's bound)
the evasion must also keep ``p_0(t) − p(t) >= p_m`` — over the **whole** horizon, ``[0, ∞)``: the ego ends in that
lane behind ``L0``. So the longitudinal profile no longer cruises after ``t_y_f``; it continues.

**The family.** ``G(u, k)``: accelerate at ``a_x_a`` on ``[0, u]``, brake at ``a_x_d`` until the ego's speed meets
that of the *followed* leader ``k ∈ {L1, L0}`` while it moves, then follow it (brake at ``a_k``, constant gap),
otherwise brake to a stop — the paper's profile (Eqs. 6–8) with the followed vehicle a choice. For a fixed ``k`` the
ego's position is non-decreasing in ``u`` at every instant, so every leader gap is non-increasing and the follower
gap non-decreasing in ``u``: the best member of each ``k`` is the largest ``u`` that keeps every leader constraint
(``L1`` on ``[0, t_y_f]`` as in the paper, ``L0`` on ``[0, ∞)``), and a safe evasion exists in ``G(·, k)`` iff the
follower constraint holds there.

**How ``u`` is found.** The paper's closed forms (:func:`~.longitudinal.longitudinal_core`) give the largest ``u``
against the followed leader on ``[0, t_y_f]`` — an upper bound. Where the other leader's constraint also holds there
(the common case) that is the answer, exactly. Elsewhere a bisection on ``[0, u_k]`` with the exact constraint
(:func:`_search`, ``SEARCH_STEPS`` = 16 halvings) keeps the lower end of its bracket, which is verified feasible:
the result is **sound** (it never accepts a profile that breaks a constraint) and short of the family's optimum by
at most ``u_k · 2⁻¹⁶`` in ``u`` (≤ 0.1 ms for ``u_k`` ≤ 6 s: the ego's position, accelerating at most ``a_x_a`` over
``t_y_f``, by well under 2 mm).

**Optimality gap.** The check is exact over ``G`` (both ``k``), not over all motions: a motion that brakes at less
than ``a_x_d``, or switches between following ``L1`` and ``L0``, is not in ``G``. Without ``L0`` the family is the
paper's and provably optimal (``docs/safety.md``); with ``L0`` the reference test
(``tests/test_own_lane.py``) measures the gap to a brute-force search over piecewise-constant profiles.

Every gap minimum is exact: each difference is piecewise quadratic, so its minimum is at ``0``, the horizon, a
breakpoint (``u``, the end of braking, a stop) or a point where the speeds are equal within a phase — all evaluated.

**One source, compiled** (docs/architecture.md). The check is written once against ``xp`` (``_backend``), in stages
each a closed form marked ``jitable``: :func:`member_bounds` (``u_k``, the gaps at ``u = 0``, whether to search),
:func:`_search` (the bisection, element-wise: a fixed ``SEARCH_STEPS`` loop of ``where``), :func:`member_parts` (the
member at its ``u``), :func:`choose_member`; the gap minima :func:`leader_gap_core`, :func:`follower_gap_core`; and
``L0`` over the shield's period, :func:`own_period`. :func:`own_lane_core` runs them on NumPy arrays (both members
stacked, the bisection on the rows that need it only); ``shield/_fast_own.py`` compiles the same functions and runs
them one row at a time (the bisection where that row needs it) — the same candidates in the same order, so the same
bits (``tests/test_fast_own.py``).
"""

from __future__ import annotations

import numpy as np

from .._motion import advance_core
from ..params import Params
from ..tolerances import SPEED_TOL_MPS
from ._backend import ARRAY, FEASIBILITY_TOL_M, INF, jitable
from .chain import braked_position
from .evasion import follower_offset
from .lateral import lateral_core
from .longitudinal import ego_position, ego_speed, longitudinal_core, profile
from .responsible import pair_min_gap_core

#: Bisection steps of the switch-time search where the closed form breaks the other leader's constraint.
SEARCH_STEPS = 16

#: Speeds this close count as equal in the tail test (round-off of a speed braked to zero at ``t2``).
SPEED_TOL = SPEED_TOL_MPS

#: The fields of one member's check (:func:`member_parts`), in the order it returns them.
MEMBER = ("exists", "lead_ok", "follow_ok", "t_x1", "v_switch", "t_brake_end", "follows_leader", "lead_gap",
          "follow_gap", "own_gap")  # fmt: skip

#: The plan's fields from the chosen member (:func:`choose_member` returns ``exists``, ``follows_own``, then these).
CHOSEN = MEMBER[1:]


def _finite(x):
    """``isfinite(x)`` with comparisons only (False for NaN), backend-generic."""
    return (x > -INF) & (x < INF)


def leader_gap_core(xp, u, p, v, lead, other, margin, horizon, prm):
    """Backend-generic :func:`leader_gap` (``lead``, ``other``: tuples ``(p, v, decel)``). The candidate instants, in
    order: 0, the profile's breakpoints ``u``, ``t2`` and the followed leader's stop (``t2`` where it is not
    followed), ``other``'s stop, the equal-speed instants of each phase, the end; a non-finite one is replaced by the
    end, each clipped to ``[0, end]``."""
    a_a, a_d = prm.a_x_a, prm.a_x_d
    pk, vk, ak = lead
    pj, vj, aj = other
    V, t2, match = profile(xp, u, p, v, pk, vk, ak, prm)
    j_stop, k_stop = xp.stop_time(vj, aj), xp.stop_time(vk, ak)
    k_end = xp.where(match, k_stop, t2)
    infinite = horizon == INF  # a horizon is t_y_f >= 0 or +inf
    last = xp.where(_finite(u), u, 0.0)
    for b in (t2, k_end, j_stop):
        last = xp.maximum(last, xp.where(_finite(b), b, 0.0))
    end = xp.where(infinite, last, horizon)
    lowest = INF
    for c in (
        0.0 * u, u, t2, k_end, j_stop,
        xp.div(vj - v, a_a + aj, 0.0),  # accelerating ego vs the leader
        xp.div(V + a_d * u - vj, a_d - aj, 0.0),  # braking ego vs the leader
        xp.div(vk - vj, ak - aj, 0.0),  # following ego vs the leader
        end,
    ):  # fmt: skip
        t = xp.clip(xp.where(_finite(c), c, end), 0.0, end)
        ego = ego_position(xp, t, p, v, u, V, t2, match, pk, vk, ak, prm, k_stop)
        lowest = xp.minimum(lowest, braked_position(xp, pj, vj, aj, t, j_stop) - ego)
    gap = lowest - margin
    # After the last breakpoint every speed is constant: the gap shrinks forever iff the ego is the faster.
    tail = end + 1.0  # any instant after the last breakpoint (speeds there are the tail's)
    ego_end = ego_speed(xp, tail, v, u, V, t2, match, vk, ak, prm)
    j_end = xp.maximum(vj - aj * tail, 0.0)
    # (A braking ego "stops" at t2 up to round-off: a speed excess below SPEED_TOL is no excess.)
    return xp.where(infinite & (ego_end > j_end + SPEED_TOL), -INF, gap)


def leader_gap(u, p, v, lead, other, margin, horizon, prm: Params):
    """Exact minimum over ``[0, horizon]`` of ``p_j(t) − p(t) − margin``: the ego on profile ``G(u, k)`` (``lead``:
    the followed leader's ``(p, v, decel)``) behind ``other`` (``(p, v, decel)`` braking until it stops).
    ``horizon`` may be ``inf``: then a gap that keeps shrinking after the last breakpoint is ``-inf``. NumPy arrays
    (:func:`leader_gap_core` on ``ARRAY``)."""
    return leader_gap_core(ARRAY, u, p, v, lead, other, margin, horizon, prm)


def follower_gap_core(xp, u, p, v, lead, f_p, f_v, aggressive, margin, horizon, prm):
    """Backend-generic :func:`follower_gap`. The candidate instants, in order: 0, ``u``, ``t2``, the followed
    leader's stop (``t2`` where it is not followed), F's stop, the equal-speed instants, the horizon; each clipped to
    ``[0, horizon]``."""
    a_a, a_d = prm.a_x_a, prm.a_x_d
    pk, vk, ak = lead
    V, t2, match = profile(xp, u, p, v, pk, vk, ak, prm)
    f_stop, k_stop = xp.stop_time(f_v, a_d), xp.stop_time(vk, ak)
    lowest = INF
    for c in (
        0.0 * u, u, t2, xp.where(match, k_stop, t2), f_stop,
        xp.div(f_v - v, a_a + a_d, 0.0),  # accelerating ego vs braking F
        xp.div(f_v - vk, a_d - ak, 0.0),  # following ego vs braking F
        horizon,
    ):  # fmt: skip
        t = xp.clip(c, 0.0, horizon)
        ego = ego_position(xp, t, p, v, u, V, t2, match, pk, vk, ak, prm, k_stop)
        lowest = xp.minimum(lowest, ego - follower_offset(xp, t, f_p, f_v, aggressive, prm, f_stop))
    return lowest - margin


def follower_gap(u, p, v, lead, f_p, f_v, aggressive, margin, horizon, prm: Params):
    """Exact minimum over ``[0, horizon]`` of ``p(t) − p_f(t) − margin`` (the worst-case ``F`` of Eq. 9 behind the
    ego on profile ``G(u, k)``). NumPy arrays (:func:`follower_gap_core` on ``ARRAY``)."""
    return follower_gap_core(ARRAY, u, p, v, lead, f_p, f_v, aggressive, margin, horizon, prm)


def leaders_gap(xp, u, p, v, lead, l0, l1, T, nothing, lead_margin, own_margin, prm):
    """Both leader constraints at switch time ``u``: ``(min(g0, g1), g1, g0)`` with ``g0`` the gap to ``L0`` over
    ``[0, ∞)`` and ``g1`` that to ``L1`` over ``[0, T]`` (``+inf`` where there is nothing to evade)."""
    g0 = leader_gap_core(xp, u, p, v, lead, l0, own_margin, INF, prm)
    if xp.row and nothing:  # (a row skips the gap the where below would discard)
        g1 = INF
    else:
        g1 = xp.where(nothing, INF, leader_gap_core(xp, u, p, v, lead, l1, lead_margin, T, prm))
    return xp.minimum(g0, g1), g1, g0


def member_switch(xp, p, v, lead, T, margin_k, prm, tol):
    """``u_k``: the paper's closed form against the followed leader ``k`` on ``[0, T]``
    (:func:`~.longitudinal.longitudinal_core`), an upper bound on member ``G(·, k)``'s best switch time."""
    return longitudinal_core(xp, p, v, lead[0], lead[1], lead[2], T, margin_k, prm, tol)[1]


def needs_search(g_hi, g_lo, tol):
    """Whether the bisection must run: the closed form breaks a leader constraint (``g_hi``, the gap at ``u_k``)
    that ``u = 0`` keeps (``g_lo``)."""
    return (g_hi < -tol) & (g_lo >= -tol)


def member_bounds(xp, p, v, lead, l0, l1, T, nothing, lead_margin, own_margin, margin_k, prm, tol):
    """The start of member ``G(·, k)`` (``lead`` the followed leader ``k``, ``margin_k`` its margin): ``(u_k, lo, hi,
    search)`` — :func:`member_switch`, :func:`leaders_gap`'s triple at ``u = 0`` (taken at ``0 · u_k``) and at
    ``u_k``, and :func:`needs_search`."""
    u_k = member_switch(xp, p, v, lead, T, margin_k, prm, tol)
    hi = leaders_gap(xp, u_k, p, v, lead, l0, l1, T, nothing, lead_margin, own_margin, prm)
    lo = leaders_gap(xp, 0.0 * u_k, p, v, lead, l0, l1, T, nothing, lead_margin, own_margin, prm)
    return u_k, lo, hi, needs_search(hi[0], lo[0], tol)


def known_gaps(u_k, g_lo, g_hi, tol):
    """Where :func:`member_parts`' leader gaps at its switch time are :func:`member_bounds`' already, so that they are
    not computed twice: ``(at_k, at_0)`` — the gaps at ``u_k`` where the member keeps ``u_k`` (``u = 0`` and ``u_k``
    both keep the leader constraints: no search), those at ``u = 0`` where ``u = 0`` breaks them and they were taken
    at ``0 · u_k = +0.0`` exactly (``u_k`` positive and finite; at ``0 · inf`` or ``−0.0`` they are taken again at
    ``0``). Elsewhere (a search, a NaN) the caller takes them at the member's switch time."""
    return (g_lo >= -tol) & (g_hi >= -tol), (g_lo < -tol) & (u_k > 0.0) & (u_k < INF)


def _search(xp, u_hi, p, v, lead, l0, l1, T, nothing, lead_margin, own_margin, prm, tol):
    """The feasible end of a ``SEARCH_STEPS``-step bisection of ``[0, u_hi]`` for the largest ``u`` whose leader gaps
    stay ``>= -tol/2`` (within ``tol`` at 0, infeasible at ``u_hi``; the gaps are non-increasing in ``u``); where no
    midpoint does, 0, whose gaps are within ``tol``. Sound: the returned ``u`` is verified; it is short of the
    family's optimum by at most ``u_hi · 2^-SEARCH_STEPS``. (The gap is not continuous in ``u`` where the profile
    stops following a leader, so a secant method gains nothing.) Element-wise: every row takes every step."""
    lo, hi = 0.0 * u_hi, u_hi
    for _ in range(SEARCH_STEPS):
        mid = 0.5 * (lo + hi)
        ok = leaders_gap(xp, mid, p, v, lead, l0, l1, T, nothing, lead_margin, own_margin, prm)[0] >= -0.5 * tol
        lo, hi = xp.where(ok, mid, lo), xp.where(ok, hi, mid)
    return lo


def member_parts(xp, u, g_lo, gaps, p, v, lead, T, nothing, f_p, f_v, aggressive, follow_margin, prm, tol):
    """Member ``G(u, k)`` checked at its switch time ``u`` (``u_k`` or the search's; 0 where even ``u = 0`` breaks a
    leader constraint, ``g_lo < -tol``), ``gaps`` :func:`leaders_gap`'s triple at that switch time: the fields
    :data:`MEMBER`."""
    u = xp.where(g_lo >= -tol, u, 0.0)
    g, g1, g0 = gaps
    lead_ok = g >= -tol
    if xp.row and nothing:  # (a row skips the gap the where below would discard)
        fg = INF
    else:
        fg = xp.where(nothing, INF, follower_gap_core(xp, u, p, v, lead, f_p, f_v, aggressive, follow_margin, T, prm))
    follow_ok = fg >= -tol
    V, t2, match = profile(xp, u, p, v, lead[0], lead[1], lead[2], prm)
    return lead_ok & follow_ok, lead_ok, follow_ok, u, V, t2, match, g1, fg, g0


def choose_member(xp, via_l1, via_l0):
    """The plan: follow ``L1`` where that member's evasion exists, else ``L0`` where that one's does, else ``L1``'s
    (failing) plan. Returns ``(exists, follows_own)`` and the fields :data:`CHOSEN`."""
    own = xp.where(via_l1[0], False, via_l0[0])
    return (
        xp.where(own, via_l0[0], via_l1[0]), own, xp.where(own, via_l0[1], via_l1[1]),
        xp.where(own, via_l0[2], via_l1[2]), xp.where(own, via_l0[3], via_l1[3]), xp.where(own, via_l0[4], via_l1[4]),
        xp.where(own, via_l0[5], via_l1[5]), xp.where(own, via_l0[6], via_l1[6]), xp.where(own, via_l0[7], via_l1[7]),
        xp.where(own, via_l0[8], via_l1[8]), xp.where(own, via_l0[9], via_l1[9]),
    )  # fmt: skip


def own_period(xp, ego_x, ego_vx, a_x, l0_x, l0_v, l0_decel, period_ok, completing, ego_vy_end, p_m, dt, tol):
    """``L0`` over the period at the candidate (the shield's check, ``shield/decide.py``): the period stays safe only
    if the ego keeps ``p_m`` behind ``L0`` braking at ``l0_decel`` at every instant of it (exact minimum, to half
    ``tol``: a follower of ``L0`` settles exactly at the margin, the executor's round-off must stay inside ``tol``);
    the step completes only moving away from ``L0`` or not at all laterally (``ego_vy_end >= 0``). Returns
    ``(period_ok, completing, l0_x', l0_v')``, ``L0``'s worst case at the period's end."""
    gap = pair_min_gap_core(xp, l0_x - ego_x - p_m, ego_vx, a_x, l0_v, -l0_decel, dt)
    l0_x_end, l0_v_end = advance_core(xp, l0_x, l0_v, -l0_decel, dt)
    return period_ok & (gap >= -0.5 * tol), completing & (ego_vy_end >= 0.0), l0_x_end, l0_v_end


def own_lane_core(
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, l0_p, l0_v, l0_decel,
    lead_margin, follow_margin, own_margin, prm: Params, tol: float = FEASIBILITY_TOL_M,
):  # fmt: skip
    """The evasion check with ``L0`` (every row has one; NumPy arrays of one batch shape ``(B,)``).

    Returns ``(exists, parts)`` like :func:`~.evasion.evasion_core`, ``parts`` with ``follows_own`` (the plan
    follows ``L0``: ``k = L0``) and ``own_gap`` (the minimum gap to ``L0`` over ``[0, ∞)`` minus its margin). Both
    members of the family (follow ``L1``, follow ``L0``) are evaluated in one stacked pass of ``2B`` rows, the search
    on the rows that need it only. The closed forms are this module's backend-generic functions; the compiled rows
    (``shield/_fast_own.py``) call the same ones in the same order, one row at a time.
    """
    xp = ARRAY
    shape = np.shape(ego_px)
    b = shape[0]
    T, t_y1, y_acc_1, y_acc_2, t_y_end = lateral_core(xp, ego_py, ego_vy, prm)
    T1 = np.broadcast_to(T, shape)
    two = lambda a: np.concatenate([np.broadcast_to(a, shape)] * 2)  # noqa: E731
    p, v, T2 = two(ego_px), two(ego_vx), two(T1)
    nothing = T2 <= 0.0
    l1 = tuple(two(a) for a in (l1_p, l1_v, l1_decel))
    l0 = tuple(two(a) for a in (l0_p, l0_v, l0_decel))
    lead = tuple(np.concatenate([np.broadcast_to(x, shape), np.broadcast_to(y, shape)])
                 for x, y in zip((l1_p, l1_v, l1_decel), (l0_p, l0_v, l0_decel), strict=True))  # fmt: skip
    lm, om = two(lead_margin), two(own_margin)
    margin_k = np.concatenate([np.broadcast_to(lead_margin, shape), np.broadcast_to(own_margin, shape)])
    u_k, lo, hi, search = member_bounds(xp, p, v, lead, l0, l1, T2, nothing, lm, om, margin_k, prm, tol)
    g_lo = lo[0]
    u = u_k.copy()
    rows = np.flatnonzero(search)
    if rows.size:  # where the closed form breaks the other leader: search [0, u_k], keeping a feasible lower end
        sub = lambda vehicle: tuple(a[rows] for a in vehicle)  # noqa: E731
        u[rows] = _search(xp, u_k[rows], p[rows], v[rows], sub(lead), sub(l0), sub(l1), T2[rows], nothing[rows],
                          lm[rows], om[rows], prm, tol)  # fmt: skip
    at_k, at_0 = known_gaps(u_k, g_lo, hi[0], tol)
    gaps = tuple(np.where(at_k, at_u_k, at_0_) for at_u_k, at_0_ in zip(hi, lo, strict=True))
    rows = np.flatnonzero(~(at_k | at_0))
    if rows.size:  # the gaps at the switch time where member_bounds did not take them there
        sub = lambda vehicle: tuple(a[rows] for a in vehicle)  # noqa: E731
        again = leaders_gap(xp, np.where(g_lo[rows] >= -tol, u[rows], 0.0), p[rows], v[rows], sub(lead), sub(l0),
                            sub(l1), T2[rows], nothing[rows], lm[rows], om[rows], prm)  # fmt: skip
        for into, part in zip(gaps, again, strict=True):
            into[rows] = part
    both = member_parts(xp, u, g_lo, gaps, p, v, lead, T2, nothing, two(f_p), two(f_v), two(aggressive),
                        two(follow_margin), prm, tol)  # fmt: skip
    exists, own, *chosen = choose_member(xp, tuple(a[:b] for a in both), tuple(a[b:] for a in both))
    parts = dict(zip(CHOSEN, chosen, strict=True))
    parts.update(
        t_y_f=T1, t_y_switch=t_y1, y_acc_1=y_acc_1, y_acc_2=y_acc_2, t_y_end=t_y_end, nothing=nothing[:b],
        follows_own=own,
    )  # fmt: skip
    return exists, parts


# The closed forms compiled into the shield's kernel (shield/_fast_own.py, through safety/_compile.py): the same
# functions, evaluated row by row.
jitable(_finite, leader_gap_core, follower_gap_core, leaders_gap, member_switch, needs_search, member_bounds,
        known_gaps, _search, member_parts, choose_member, own_period)  # fmt: skip
