"""Independent numeric reference for the worst-case safety engine (``safelane.safety``). Test helper, not tests.

Nothing here imports the engine or reuses its closed forms (the paper's Eqs. 2, 5 and 7, or the corrected
versions in the engine's docstrings). The only physics is constant-acceleration kinematics over one substep,
with vehicles stopping rather than reversing; every unknown — a follower's required deceleration, a switch
time, a lateral crossing time — is found by **bisection** on a simulated, monotone quantity.

How a scenario is simulated. Time is stepped on a grid of ``n_grid`` uniform nodes over the horizon plus the
scenario's *event* times (switch time, start of following, each vehicle's stop), so that inside every substep
each vehicle's acceleration is constant. Each substep is integrated exactly (``p += v h + a h²/2``, cut short
where a braking vehicle comes to rest). The gap between two vehicles is then an exact quadratic on every
substep, so its minimum over the horizon is the smallest node value or, on a substep where the relative speed
changes sign from closing to opening, that substep's vertex ``g_j − g'_j² / (2 g'')`` — a generic one-substep
refinement of the grid minimum, exact up to round-off, that knows nothing about which physical case binds.

Everything is vectorized over one leading batch axis (1-D arrays ``(B,)``); parameters are a
:class:`safelane.Params` (only its fields are read).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Bisection iterations on a bracket of times [s] (the bracket shrinks to ~1e-15 of its length).
BISECT_ITERS = 52
#: Log-space bisection bracket and iterations for a required deceleration [m/s²].
Z_MIN, Z_MAX, Z_ITERS = 1e-9, 1e7, 56
#: Uniform grid nodes per simulated horizon (event times are added on top).
N_GRID = 33


# --------------------------------------------------------------------------------------------------------------
# Time stepping
# --------------------------------------------------------------------------------------------------------------


def stop_time(v, decel):
    """Time for a vehicle at speed ``v`` braking at ``decel`` to come to rest (``inf`` if it never does)."""
    v = np.asarray(v, dtype=np.float64)
    decel = np.broadcast_to(np.asarray(decel, dtype=np.float64), v.shape)
    out = np.full(v.shape, np.inf)
    out[v <= 0.0] = 0.0
    braking = (decel > 0.0) & (v > 0.0)
    out[braking] = v[braking] / decel[braking]
    return out


def time_nodes(t_end, events, n_grid=N_GRID):
    """Sorted ``(B, n_grid + len(events))`` time nodes: a uniform grid on ``[0, t_end]`` plus event times."""
    t_end = np.asarray(t_end, dtype=np.float64)
    frac = np.linspace(0.0, 1.0, n_grid)
    cols = [t_end[:, None] * frac[None, :]]
    cols += [np.clip(e, 0.0, t_end)[:, None] for e in events]
    return np.sort(np.concatenate(cols, axis=1), axis=1)


def midpoints(nodes):
    return 0.5 * (nodes[:, 1:] + nodes[:, :-1])


def braking_acc(mid, decel, t_stop):
    """Per-substep acceleration of a vehicle braking at ``decel`` until ``t_stop``, at rest afterwards."""
    return np.where(mid < t_stop[:, None], -np.asarray(decel, dtype=np.float64)[:, None], 0.0)


def integrate(nodes, p0, v0, acc):
    """Exact time stepping: ``acc`` ``(B, G-1)`` is constant on each substep between the ``(B, G)`` nodes.

    Returns positions and speeds at the nodes. Speeds never go below zero: a braking vehicle that reaches rest
    inside a substep (only round-off can make that happen between event nodes) stays at rest.
    """
    h = np.diff(nodes, axis=1)
    v = np.concatenate([v0[:, None], v0[:, None] + np.cumsum(acc * h, axis=1)], axis=1)
    v = np.maximum(v, 0.0)
    vs = v[:, :-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_rest = np.where(acc < 0.0, vs / -acc, np.inf)
    hh = np.minimum(h, t_rest)
    dp = vs * hh + 0.5 * acc * hh * hh
    p = np.concatenate([p0[:, None], p0[:, None] + np.cumsum(dp, axis=1)], axis=1)
    return p, v


def gap_minimum(nodes, p_front, v_front, a_front, p_back, v_back, a_back):
    """Exact minimum over the nodes' span of ``p_front − p_back``; returns ``(min, time_of_min)``."""
    g = p_front - p_back
    gd = v_front - v_back
    c = a_front - a_back
    vertex = (gd[:, :-1] < 0.0) & (gd[:, 1:] > 0.0) & (c > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        safe_c = np.where(vertex, c, 1.0)
        g_vertex = np.where(vertex, g[:, :-1] - gd[:, :-1] ** 2 / (2.0 * safe_c), np.inf)
        t_vertex = nodes[:, :-1] - gd[:, :-1] / safe_c
    cand = np.concatenate([g, g_vertex], axis=1)
    times = np.concatenate([nodes, t_vertex], axis=1)
    k = np.argmin(cand, axis=1)
    rows = np.arange(g.shape[0])
    return cand[rows, k], times[rows, k]


def braked_position(p, v, decel, t, n_grid=N_GRID):
    """Position after ``t`` of a vehicle braking at ``decel`` from ``(p, v)``, stopping at rest (time-stepped)."""
    p, v, decel, t = (np.asarray(x, dtype=np.float64) for x in np.broadcast_arrays(p, v, decel, t))
    ts = stop_time(v, decel)
    nodes = time_nodes(t, [ts], n_grid)
    pos, _ = integrate(nodes, p, v, braking_acc(midpoints(nodes), decel, ts))
    return pos[:, -1]


def follower_position(p, v, aggressive, t, params, n_grid=N_GRID):
    """Worst-case follower after ``t`` (time-stepped): ``+a_x_a`` if aggressive, else brakes at ``a_x_d`` to rest."""
    p, v, aggressive, t = np.broadcast_arrays(p, v, aggressive, t)
    p, v, t = (np.asarray(x, dtype=np.float64) for x in (p, v, t))
    aggressive = np.asarray(aggressive, dtype=bool)
    ts = np.where(aggressive, np.inf, stop_time(v, params.a_x_d))
    nodes = time_nodes(t, [ts], n_grid)
    acc = np.where(aggressive[:, None], params.a_x_a, braking_acc(midpoints(nodes), np.full(p.shape, params.a_x_d), ts))
    pos, _ = integrate(nodes, p, v, acc)
    return pos[:, -1]


# --------------------------------------------------------------------------------------------------------------
# Leader chain (Eqs. 1–3)
# --------------------------------------------------------------------------------------------------------------


def follow_gap_margin(z, p_f, v_f, p_l, v_l, a_l, margin, n_grid=N_GRID):
    """Smallest ``gap − margin`` over all time when the follower brakes at ``z`` and the leader at ``a_l``.

    Both stop and stay stopped. Returns ``(margin_min, t_at_min, t_leader_stop, t_follower_stop)``. The horizon
    ends when both have stopped (if the leader never stops, when the follower does: the gap only grows then).
    """
    t_fs = stop_time(v_f, z)
    t_ls = stop_time(v_l, a_l)
    horizon = np.where(np.isfinite(t_ls), np.maximum(t_fs, t_ls), t_fs)
    nodes = time_nodes(horizon, [t_fs, t_ls], n_grid)
    mid = midpoints(nodes)
    a_back = braking_acc(mid, z, t_fs)
    a_front = braking_acc(mid, a_l, t_ls)
    pb, vb = integrate(nodes, p_f, v_f, a_back)
    pf, vf = integrate(nodes, p_l, v_l, a_front)
    gmin, t_min = gap_minimum(nodes, pf, vf, a_front, pb, vb, a_back)
    return gmin - margin, t_min, t_ls, t_fs


@dataclass(frozen=True)
class RefFollowDecel:
    """``z``: least follower deceleration (``inf`` where the gap is already at or below the margin, ``0`` where
    none is needed); ``interior``: at that ``z`` the gap is smallest while both still move (speeds equal), not
    once both have stopped; ``full_brake_margin``: ``gap − margin`` minimum when the follower brakes at ``a_x_d``
    (the distance of the chain's unsafe verdict from its boundary)."""

    z: np.ndarray
    interior: np.ndarray
    full_brake_margin: np.ndarray


def ref_min_follow_decel(p_f, v_f, p_l, v_l, a_l, margin, a_x_d):
    """Least constant deceleration keeping a follower ``margin`` behind a leader braking at ``a_l`` (bisection).

    ``f(z) = min_t gap − margin`` is non-decreasing in ``z`` (harder braking puts the follower further back at
    every instant); ``z`` is the smallest value with ``f(z) >= 0``, found by bisection on ``log z`` over
    ``[Z_MIN, Z_MAX]``.
    """
    p_f, v_f, p_l, v_l, a_l, margin = (
        np.asarray(x, dtype=np.float64) for x in np.broadcast_arrays(p_f, v_f, p_l, v_l, a_l, margin)
    )
    # Convention shared with the library: gaps within 1 nm of the margin count as kept; at a slack of at most
    # 0.5 nm the follower keeps the gap above margin - 0.5 nm (half a nanometre more slack, clamped at 0 down to
    # -1 nm).
    slack = p_l - p_f - margin
    shifted = np.where((slack >= -1e-9) & (slack <= 5e-10), np.maximum(slack + 5e-10, 0.0), slack)
    p_l = p_l + (shifted - slack)
    args = (p_f, v_f, p_l, v_l, a_l, margin)
    # At the margin a pair can keep it only if it is not closing (the bisection below decides); inside, never.
    already_close = (p_l - p_f - margin < 0.0) | ((p_l - p_f - margin <= 0.0) & (v_f > v_l))
    full, *_ = follow_gap_margin(np.full(p_f.shape, a_x_d), *args)
    lo = np.full(p_f.shape, np.log(Z_MIN))
    hi = np.full(p_f.shape, np.log(Z_MAX))
    none_needed = follow_gap_margin(np.exp(lo), *args)[0] >= 0.0
    too_much = follow_gap_margin(np.exp(hi), *args)[0] < 0.0
    for _ in range(Z_ITERS):
        mid = 0.5 * (lo + hi)
        ok = follow_gap_margin(np.exp(mid), *args)[0] >= 0.0
        hi = np.where(ok, mid, hi)
        lo = np.where(ok, lo, mid)
    z = np.exp(hi)
    _, t_min, t_ls, t_fs = follow_gap_margin(z, *args)
    interior = (t_min > 0.0) & (t_min < t_ls * (1.0 - 1e-9)) & (t_min < t_fs * (1.0 - 1e-9))
    z = np.where(none_needed, 0.0, z)
    z = np.where(already_close | too_much, np.inf, z)
    return RefFollowDecel(z=z, interior=interior & ~none_needed & ~already_close, full_brake_margin=full)


@dataclass(frozen=True)
class RefChain:
    """Reference chain result; link arrays are ``(B, N)`` (``L1..LN``), ``decel`` is ``(B, N+1)``."""

    decel: np.ndarray
    required: np.ndarray
    unsafe: np.ndarray
    l1_decel: np.ndarray
    interior: np.ndarray
    full_brake_margin: np.ndarray


def others_max(params):
    """The others' maximum braking: ``Params.a_o_d``, or ``a_x_d`` where it is not set (read from the fields)."""
    return params.a_x_d if params.a_o_d is None else params.a_o_d


def ref_leader_chain(p, v, promise, params, human=None):
    """Propagate the worst case from ``L(N+1)`` (brakes at the others' maximum ``a_o``: ``a_o_d``, else ``a_x_d``)
    to ``L1``.

    ``p, v``: ``(B, N+1)`` ordered front-last; ``promise``: ``(B, N)``; ``human``: ``(B, N)`` bool (margin
    ``p_m_human`` instead of ``p_m``). ``L_i`` brakes at ``max(promise_i, z_i)`` (capped at ``a_o``, what any other
    vehicle can brake); the chain is unsafe when some gap is already at or below its margin or some ``z_i > a_o``,
    and then ``L1``'s worst case is ``a_o``.
    """
    p, v, promise = (np.asarray(x, dtype=np.float64) for x in (p, v, promise))
    b, n = promise.shape
    human = np.zeros((b, n), dtype=bool) if human is None else np.asarray(human, dtype=bool)
    a_o = others_max(params)
    a_ahead = np.full(b, a_o)
    decel = [a_ahead]
    required, interior, full = [], [], []
    unsafe = np.zeros(b, dtype=bool)
    for i in range(n - 1, -1, -1):
        margin = np.where(human[:, i], params.p_m_human, params.p_m)
        r = ref_min_follow_decel(p[:, i], v[:, i], p[:, i + 1], v[:, i + 1], a_ahead, margin, a_o)
        unsafe = unsafe | ~(r.z <= a_o)
        a_ahead = np.minimum(np.maximum(promise[:, i], r.z), a_o)
        decel.insert(0, a_ahead)
        required.insert(0, r.z)
        interior.insert(0, r.interior)
        full.insert(0, r.full_brake_margin)

    def stack(xs, dtype=np.float64):
        return np.stack(xs, axis=1) if xs else np.zeros((b, 0), dtype=dtype)

    return RefChain(
        decel=stack(decel),
        required=stack(required),
        unsafe=unsafe,
        l1_decel=np.where(unsafe, a_o, decel[0]),
        interior=stack(interior, bool),
        full_brake_margin=stack(full),
    )


# --------------------------------------------------------------------------------------------------------------
# Lateral return (Eq. 5)
# --------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RefLateral:
    """``case``: 0 nothing to evade, 1 bang-bang (stop exactly at ``y_s``), 2 returning fast (cannot stop at
    ``y_s``); ``peak``: highest intrusion ``y − y_s`` under full lateral braking (the nothing-to-evade boundary
    is ``peak = 0``)."""

    t_y_f: np.ndarray
    t_switch: np.ndarray
    case: np.ndarray
    peak: np.ndarray


def _kin(x, v, a, t):
    return x + v * t + 0.5 * a * t * t


def ref_lateral_time(p_y, v_y, params):
    """First instant from which the ego stays at ``y <= y_s = (w_l − w_v)/2``, lateral acceleration in ``±a_y_m``.

    Terminal-speed rule (lateral.py): among the profiles that get the ego back, take those reaching ``y_s``
    with the smallest lateral speed, then the fastest of them. If full lateral braking already keeps the ego at
    or below ``y_s`` there is nothing to evade (``0``). If braking would bring it to rest above ``y_s`` it can
    arrive at rest: it accelerates toward its lane until a switch time, then brakes to rest; the switch time at
    which it comes to rest exactly at ``y_s`` is found by bisection (the rest point decreases with it). Otherwise
    (already moving back too fast to stop at ``y_s``) it brakes throughout and the time is the first crossing of
    ``y_s``, found by bisection on the still-descending part of the path. Works in the intrusion ``e = y − y_s``.
    """
    p_y, v_y = (np.asarray(x, dtype=np.float64) for x in np.broadcast_arrays(p_y, v_y))
    a = params.a_y_m
    e = p_y - 0.5 * (params.lane_width - params.vehicle_width)
    # Full braking of the lateral speed: -a while moving out, +a while moving back; rest after |v|/a.
    t_rest = np.abs(v_y) / a
    brake = np.where(v_y > 0.0, -a, a)
    rest = _kin(e, v_y, brake, t_rest)
    peak = np.where(v_y > 0.0, rest, e)
    nothing = peak <= 0.0
    bang = ~nothing & (rest > 0.0)  # else, if not nothing: returning fast

    def rest_after_switch(t1):
        e1, v1 = _kin(e, v_y, -a, t1), v_y - a * t1  # v1 <= 0 for t1 >= max(v_y, 0)/a
        return _kin(e1, v1, a, -v1 / a)

    lo = np.maximum(v_y, 0.0) / a
    span = np.ones_like(e)
    for _ in range(200):  # doubling to bracket the switch time
        short = bang & (rest_after_switch(lo + span) > 0.0)
        if not short.any():
            break
        span = np.where(short, 2.0 * span, span)
    hi = lo + span
    for _ in range(BISECT_ITERS + 12):
        mid = 0.5 * (lo + hi)
        above = rest_after_switch(mid) > 0.0
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    t1 = 0.5 * (lo + hi)
    t_bang = t1 + (a * t1 - v_y) / a

    lo_b = np.zeros_like(e)
    hi_b = t_rest.copy()
    for _ in range(BISECT_ITERS + 12):
        mid = 0.5 * (lo_b + hi_b)
        above = _kin(e, v_y, a, mid) > 0.0
        lo_b = np.where(above, mid, lo_b)
        hi_b = np.where(above, hi_b, mid)
    t_back = 0.5 * (lo_b + hi_b)

    t_y_f = np.where(nothing, 0.0, np.where(bang, t_bang, t_back))
    t_switch = np.where(bang, t1, 0.0)
    case = np.where(nothing, 0, np.where(bang, 1, 2)).astype(np.int8)
    return RefLateral(t_y_f=t_y_f, t_switch=t_switch, case=case, peak=peak)


# --------------------------------------------------------------------------------------------------------------
# Longitudinal evasion behind L1 (Eqs. 6–8) and the follower check (Eq. 9)
# --------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Profile:
    """Events of the accelerate → brake → follow-L1 profile with switch time ``u``."""

    u: np.ndarray
    brake_end: np.ndarray  # start of following, or the ego's stop
    match: np.ndarray  # the ego follows L1 after brake_end
    l1_stop: np.ndarray


def _profile(u, v, v1, a1, params, iters=BISECT_ITERS):
    """Find when the braking ego's speed comes down to L1's (bisection) and whether L1 still moves then (and brakes
    no harder than the ego can follow)."""
    a_a, a_d = params.a_x_a, params.a_x_d
    big_v = v + a_a * u

    def speed_excess(t):  # ego speed minus L1 speed while the ego brakes from u
        return np.maximum(big_v - a_d * (t - u), 0.0) - np.maximum(v1 - a1 * t, 0.0)

    ego_stop = u + big_v / a_d
    faster = speed_excess(u) >= 0.0
    lo, hi = u.copy(), ego_stop.copy()
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        down = speed_excess(mid) <= 0.0
        hi = np.where(down, mid, hi)
        lo = np.where(down, lo, mid)
    t_meet = np.where(speed_excess(u) <= 0.0, u, hi)
    l1_moving = np.maximum(v1 - a1 * t_meet, 0.0) > 0.0
    # Following means braking as L1 does: the ego commits to no more than a_x_d, so an L1 braking harder (the others'
    # maximum above the ego's) is never followed.
    match = faster & l1_moving & (a1 <= a_d)
    return _Profile(u=u, brake_end=np.where(match, t_meet, ego_stop), match=match, l1_stop=stop_time(v1, a1))


def _simulate(prof, p, v, p1, v1, a1, T, params, extra_events=(), n_grid=N_GRID):
    """Time-step ego and L1 over ``[0, T]``; returns ``nodes, mid, (pE, vE, aE), (pL, vL, aL)``."""
    nodes = time_nodes(T, [prof.u, prof.brake_end, prof.l1_stop, *extra_events], n_grid)
    mid = midpoints(nodes)
    a_l1 = braking_acc(mid, a1, prof.l1_stop)
    follow = np.where(prof.match[:, None], a_l1, 0.0)
    a_ego = np.where(
        mid < prof.u[:, None], params.a_x_a, np.where(mid < prof.brake_end[:, None], -params.a_x_d, follow)
    )
    pe, ve = integrate(nodes, p, v, a_ego)
    pl, vl = integrate(nodes, p1, v1, a_l1)
    return nodes, mid, (pe, ve, a_ego), (pl, vl, a_l1)


def leader_gap_margin(u, p, v, p1, v1, a1, T, margin, params):
    """Smallest ``p_1 − p − margin`` over ``[0, T]`` for switch time ``u`` (time-stepped)."""
    prof = _profile(u, v, v1, a1, params)
    nodes, _, ego, lead = _simulate(prof, p, v, p1, v1, a1, T, params)
    g, _ = gap_minimum(nodes, *lead, *ego)
    return g - margin


@dataclass(frozen=True)
class RefLongitudinal:
    """``t_x1``: largest feasible switch time (``0`` where infeasible); ``full_brake_margin``: leader-gap margin
    when braking from ``t = 0`` (feasibility is ``>= 0``); ``case``: the paper's Figure 3 labels as in the
    engine (0 accelerate throughout, 1 braking at ``T``, 2 stopped before ``T``, 3 following a moving L1 at
    ``T``, 4 following L1 to rest before ``T``, −1 infeasible); ``case_margin``: how far (s) the result is from
    a case boundary (small values make the label ambiguous)."""

    feasible: np.ndarray
    t_x1: np.ndarray
    t_x2: np.ndarray
    min_gap: np.ndarray
    full_brake_margin: np.ndarray
    case: np.ndarray
    case_margin: np.ndarray
    profile: _Profile


def ref_longitudinal(ego_px, ego_vx, l1_p, l1_v, l1_decel, T, params, margin=None):
    """Largest ``t_x1 ∈ [0, T]`` whose accelerate(``a_x_a``) → brake(``a_x_d``) → follow-L1 profile keeps the gap to
    L1 ``>= margin`` on ``[0, T]`` (bisection; the minimum gap is non-increasing in ``t_x1`` because a later
    switch leaves the ego ahead at every instant). Infeasible where ``t_x1 = 0`` already fails.
    """
    arrs = np.broadcast_arrays(ego_px, ego_vx, l1_p, l1_v, l1_decel, T)
    p, v, p1, v1, a1, T = (np.asarray(x, dtype=np.float64).copy() for x in arrs)
    margin = np.broadcast_to(np.asarray(params.p_m if margin is None else margin, dtype=np.float64), p.shape)
    args = (p, v, p1, v1, a1, T, margin, params)
    zero = np.zeros_like(T)
    g0 = leader_gap_margin(zero, *args)
    feasible = g0 >= 0.0
    all_the_way = leader_gap_margin(T, *args) >= 0.0
    lo, hi = zero.copy(), T.copy()
    for _ in range(BISECT_ITERS):
        mid = 0.5 * (lo + hi)
        ok = leader_gap_margin(mid, *args) >= 0.0
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    u = np.where(feasible, np.where(all_the_way, T, lo), 0.0)
    prof = _profile(u, v, v1, a1, params)
    gap = leader_gap_margin(u, *args) + margin

    case = np.where(
        u >= T, 0, np.where(prof.brake_end >= T, 1, np.where(prof.match, np.where(prof.l1_stop >= T, 3, 4), 2))
    )
    case = np.where(feasible, case, -1).astype(np.int8)
    # Distance (s) of the label from its boundaries: u vs T, the end of braking vs T, L1's stop vs both.
    dist = np.minimum(T - u, np.abs(prof.brake_end - T))
    dist = np.minimum(dist, np.minimum(np.abs(prof.l1_stop - prof.brake_end), np.abs(prof.l1_stop - T)))
    case_margin = np.where((case == 0) | (case == -1), np.inf, dist)
    return RefLongitudinal(
        feasible=feasible,
        t_x1=u,
        t_x2=np.minimum(prof.brake_end, T),
        min_gap=gap,
        full_brake_margin=g0,
        case=case,
        case_margin=case_margin,
        profile=prof,
    )


@dataclass(frozen=True)
class RefEvasion:
    """``exists``: verdict; ``lateral``/``longitudinal``: the parts; ``follower_min_gap``: smallest ego − F gap
    on ``[0, t_y_f]`` along the longitudinal plan (at ``t_x1 = 0`` where the leader constraint is infeasible)."""

    exists: np.ndarray
    lateral: RefLateral
    longitudinal: RefLongitudinal
    follower_min_gap: np.ndarray


def ref_follower_gap(lon, ego_px, ego_vx, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, T, params):
    """Exact minimum of ``p_ego − p_F`` on ``[0, T]`` along the reference plan ``lon`` (time-stepped)."""
    f_stop = np.where(aggressive, np.inf, stop_time(f_v, params.a_x_d))
    nodes, mid, ego, _ = _simulate(lon.profile, ego_px, ego_vx, l1_p, l1_v, l1_decel, T, params, [f_stop])
    a_f = np.where(aggressive[:, None], params.a_x_a, braking_acc(mid, np.full(T.shape, params.a_x_d), f_stop))
    pf, vf = integrate(nodes, f_p, f_v, a_f)
    g, _ = gap_minimum(nodes, *ego, pf, vf, a_f)
    return g


def ref_evasion_exists(
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, params, lead_margin, follow_margin
):
    """Does an evasion exist (Eq. 9 check)? Lateral return time by :func:`ref_lateral_time`, longitudinal plan by
    :func:`ref_longitudinal`, then the follower's worst case (``+a_x_a`` if aggressive, else brake at ``a_x_d``
    to rest) checked against the plan over the whole of ``[0, t_y_f]``. Nothing to evade counts as existing.
    """
    arrs = np.broadcast_arrays(
        ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, lead_margin, follow_margin
    )
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, lead_margin, follow_margin = (
        np.asarray(x, dtype=np.float64) for x in arrs
    )
    aggressive = np.broadcast_to(np.asarray(aggressive, dtype=bool), ego_px.shape)
    lat = ref_lateral_time(ego_py, ego_vy, params)
    T = lat.t_y_f
    lon = ref_longitudinal(ego_px, ego_vx, l1_p, l1_v, l1_decel, T, params, lead_margin)
    g_f = ref_follower_gap(lon, ego_px, ego_vx, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, T, params)
    exists = (lat.case == 0) | (lon.feasible & (g_f - follow_margin >= 0.0))
    return RefEvasion(exists=exists, lateral=lat, longitudinal=lon, follower_min_gap=g_f)
