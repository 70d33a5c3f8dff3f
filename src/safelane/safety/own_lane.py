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
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ._backend import ARRAY, FEASIBILITY_TOL_M, INF
from .chain import braked_position
from .evasion import follower_offset
from .lateral import lateral_core
from .longitudinal import ego_position, ego_speed, longitudinal_core, profile

#: Bisection steps of the switch-time search where the closed form breaks the other leader's constraint.
SEARCH_STEPS = 16

#: Speeds this close count as equal in the tail test (round-off of a speed braked to zero at ``t2``).
SPEED_TOL = 1e-9

xp = ARRAY


def _stationary(num, den):
    """``num / den`` where ``den != 0``, else 0 (a harmless extra candidate)."""
    return np.where(den != 0.0, num / np.where(den != 0.0, den, 1.0), 0.0)


def _profile_candidates(u, V, t2, match, lead, prm: Params):
    """The ego's breakpoints on profile ``(u, followed lead)``: ``[u, t2, stop of the followed leader if followed]``."""
    _, vk, ak = lead
    k_stop = xp.stop_time(vk, ak)
    return [u, t2, np.where(match, k_stop, t2)]


def leader_gap(u, p, v, lead, other, margin, horizon, prm: Params):
    """Exact minimum over ``[0, horizon]`` of ``p_j(t) − p(t) − margin``: the ego on profile ``G(u, k)`` (``lead``:
    the followed leader's ``(p, v, decel)``) behind ``other`` (``(p, v, decel)`` braking until it stops).
    ``horizon`` may be ``inf``: then a gap that keeps shrinking after the last breakpoint is ``-inf``."""
    a_a, a_d = prm.a_x_a, prm.a_x_d
    pk, vk, ak = lead
    pj, vj, aj = other
    V, t2, match = profile(xp, u, p, v, pk, vk, ak, prm)
    j_stop = xp.stop_time(vj, aj)
    breaks = [*_profile_candidates(u, V, t2, match, lead, prm), j_stop]
    stationary = [
        _stationary(vj - v, a_a + aj),  # accelerating ego vs the leader
        _stationary(V + a_d * u - vj, a_d - aj),  # braking ego vs the leader
        _stationary(vk - vj, ak - aj),  # following ego vs the leader
    ]
    horizon = np.broadcast_to(horizon, np.shape(u)) if np.ndim(horizon) < np.ndim(u) else horizon
    infinite = np.isinf(horizon)
    finite_breaks = [np.where(np.isfinite(b), b, 0.0) for b in breaks]
    last = np.maximum.reduce(np.broadcast_arrays(*finite_breaks))
    end = np.where(infinite, last, horizon)
    cands = np.stack(np.broadcast_arrays(0.0 * u, *breaks, *stationary, end))
    t = np.clip(np.where(np.isfinite(cands), cands, end), 0.0, end)
    ego = ego_position(xp, t, p, v, u, V, t2, match, pk, vk, ak, prm)
    gap = (braked_position(xp, pj, vj, aj, t, j_stop) - ego).min(0) - margin
    # After the last breakpoint every speed is constant: the gap shrinks forever iff the ego is the faster.
    tail = end + 1.0  # any instant after the last breakpoint (speeds there are the tail's)
    ego_end = ego_speed(xp, tail, v, u, V, t2, match, vk, ak, prm)
    j_end = xp.maximum(vj - aj * tail, 0.0)
    # (A braking ego "stops" at t2 up to round-off: a speed excess below SPEED_TOL is no excess.)
    return np.where(infinite & (ego_end > j_end + SPEED_TOL), -INF, gap)


def follower_gap(u, p, v, lead, f_p, f_v, aggressive, margin, horizon, prm: Params):
    """Exact minimum over ``[0, horizon]`` of ``p(t) − p_f(t) − margin`` (the worst-case ``F`` of Eq. 9 behind the
    ego on profile ``G(u, k)``)."""
    a_a, a_d = prm.a_x_a, prm.a_x_d
    pk, vk, ak = lead
    V, t2, match = profile(xp, u, p, v, pk, vk, ak, prm)
    f_stop = xp.stop_time(f_v, a_d)
    cands = [
        0.0 * u,
        *_profile_candidates(u, V, t2, match, lead, prm),
        f_stop,
        _stationary(f_v - v, a_a + a_d),  # accelerating ego vs braking F
        _stationary(f_v - vk, a_d - ak),  # following ego vs braking F
        horizon,
    ]
    t = np.clip(np.stack(np.broadcast_arrays(*cands)), 0.0, horizon)
    ego = ego_position(xp, t, p, v, u, V, t2, match, pk, vk, ak, prm)
    return (ego - follower_offset(xp, t, f_p, f_v, aggressive, prm, f_stop)).min(0) - margin


def _search(fixed, u_hi, prm: Params, tol: float):
    """The feasible end of a ``SEARCH_STEPS``-step bisection of ``[0, u_hi]`` for the largest ``u`` whose leader gaps
    stay ``>= -tol/2`` (within ``tol`` at 0, infeasible at ``u_hi``; the gaps are non-increasing in ``u``); where no
    midpoint does, 0, whose gaps are within ``tol``. Sound: the returned ``u`` is verified; it is short of the
    family's optimum by at most ``u_hi · 2^-SEARCH_STEPS``. (The gap is not continuous in ``u`` where the profile
    stops following a leader, so a secant method gains nothing.)"""
    p, v, lead, l0, l1, nothing, T, lead_margin, own_margin = fixed
    lo, hi = np.zeros_like(u_hi), u_hi.copy()
    for _ in range(SEARCH_STEPS):
        mid = 0.5 * (lo + hi)
        g0 = leader_gap(mid, p, v, lead, l0, own_margin, INF, prm)
        g1 = np.where(nothing, INF, leader_gap(mid, p, v, lead, l1, lead_margin, T, prm))
        ok = np.minimum(g0, g1) >= -0.5 * tol
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return lo


def own_lane_core(
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, l0_p, l0_v, l0_decel,
    lead_margin, follow_margin, own_margin, prm: Params, tol: float = FEASIBILITY_TOL_M,
):  # fmt: skip
    """The evasion check with ``L0`` (every row has one; arrays of one batch shape ``(B,)``).

    Returns ``(exists, parts)`` like :func:`~.evasion.evasion_core`, ``parts`` with ``follows_own`` (the plan
    follows ``L0``: ``k = L0``) and ``own_gap`` (the minimum gap to ``L0`` over ``[0, ∞)`` minus its margin). Both
    members of the family (follow ``L1``, follow ``L0``) are evaluated in one stacked pass of ``2B`` rows.
    """
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

    def leaders_gap(u):
        g0 = leader_gap(u, p, v, lead, l0, om, INF, prm)
        g1 = np.where(nothing, INF, leader_gap(u, p, v, lead, l1, lm, T2, prm))
        return np.minimum(g0, g1), g1, g0

    # The closed form against the followed leader on [0, t_y_f]: an upper bound on the best u.
    _, u_k, *_ = longitudinal_core(xp, p, v, *lead, T2, margin_k, prm, tol)
    g_hi = leaders_gap(u_k)[0]
    g_lo = leaders_gap(0.0 * u_k)[0]
    u = u_k.copy()
    rows = np.flatnonzero((g_hi < -tol) & (g_lo >= -tol))
    if rows.size:  # where the closed form breaks the other leader: search [0, u_k], keeping a feasible lower end
        fixed = (p[rows], v[rows], tuple(a[rows] for a in lead), tuple(a[rows] for a in l0),
                 tuple(a[rows] for a in l1), nothing[rows], T2[rows], lm[rows], om[rows])  # fmt: skip
        u[rows] = _search(fixed, u_k[rows], prm, tol)
    u = np.where(g_lo >= -tol, u, 0.0)
    g, g1, g0 = leaders_gap(u)
    lead_ok = g >= -tol
    fg = np.where(nothing, INF, follower_gap(u, p, v, lead, two(f_p), two(f_v), two(aggressive), two(follow_margin),
                                             T2, prm))  # fmt: skip
    follow_ok = fg >= -tol
    V, t2, match = profile(xp, u, p, v, *lead, prm)
    both = dict(exists=lead_ok & follow_ok, lead_ok=lead_ok, follow_ok=follow_ok, t_x1=u, v_switch=V,
                t_brake_end=t2, follows_leader=match, lead_gap=g1, follow_gap=fg, own_gap=g0)  # fmt: skip
    results = [{k: a[:b] for k, a in both.items()}, {k: a[b:] for k, a in both.items()}]
    nothing = nothing[:b]
    T = T1
    via_l1, via_l0 = results
    own = ~via_l1["exists"] & via_l0["exists"]
    parts = {k: np.where(own, via_l0[k], via_l1[k]) for k in via_l1}
    exists = parts.pop("exists")
    parts.update(
        t_y_f=T, t_y_switch=t_y1, y_acc_1=y_acc_1, y_acc_2=y_acc_2, t_y_end=t_y_end, nothing=nothing,
        follows_own=own,
    )  # fmt: skip
    return exists, parts
