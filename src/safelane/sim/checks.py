"""Exact per-period safety bookkeeping: ego collisions / p_m violations and target-lane pair checks.

Collisions are physical overlap of footprints (longitudinal ``|dx| < vehicle_length`` at an instant when the
ego overlaps the target lane laterally); violations are ``|dx| < p_m`` at an instant when the ego is in the
conflict zone. Both are evaluated in continuous time within the period.

**One source.** Each rule per pair is written once against the backend ``xp`` (:mod:`safelane.safety._backend`) and
marked ``jitable``: which pairs are near (:func:`near_threshold`, :func:`near_pair`, :func:`lane_near`), the sampled
gaps of the far ones (:func:`far_gap`, :func:`lane_far_ratio`), which closed form a near pair takes
(:func:`ego_pair_kind`), the closed forms (:func:`quadratic_extrema`, :func:`windowed_quadratic` with
:func:`window_crossings`, :func:`stop_pair_extrema`) and the verdicts (:func:`ego_verdict`, :func:`lane_verdict`).
:func:`ego_checks` and :func:`lane_checks` evaluate them on NumPy arrays, pair by pair through masks; the compiled
kernels (:mod:`._fast_checks`) and the compiled closed loop call them per row.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, INF, jitable
from ..safety.evasion import fast_kernel
from ..shield.decide import lateral_max
from ..tolerances import DIST_TOL_M
from .kinematics import (
    Fleet,
    Motion,
    crossing_knots,
    extrema,
    gap_extrema,
    piece_extrema,
    segment_crossings,
    state_at,
    vertex_extrema,
    windowed_gap_extrema,
)


def _rows(m: Motion, rows) -> Motion:
    return Motion(*(getattr(m, f)[rows] for f in ("t", "x", "v", "acc")))


#: :func:`ego_checks` runs the compiled kernel (:mod:`._fast_checks`) from this many scenarios on.
FAST_MIN_ROWS = 64


def checks_kernel():
    """The compiled checks' module :mod:`._fast_checks`, or ``None`` where
    :func:`~safelane.safety.evasion.fast_kernel` is ``None`` (numba missing, or ``SAFELANE_NO_NUMBA=1``)."""
    if fast_kernel() is None:
        return None
    from . import _fast_checks

    return _fast_checks


def ego_checks(
    b,
    prm: Params,
    s,
    lon: Motion,
    lat: Motion,
    others: Fleet,
    conflict_level: float,
    overlap_level: float,
    plan=None,
):
    """Exact ego collision / p_m-violation checks for the period, counted only at the instants the ego is
    in the conflict zone (violations) or overlaps the target lane's vehicles laterally (collisions).

    ``lon``, ``lat``: the ego's constant-command motions (:meth:`Motion.constant`, :meth:`Motion.free`);
    ``plan``: ``(rows, plan_lon, plan_lat)`` for the rows executing an evasion plan instead (multi-segment motions,
    see :func:`~safelane.shield.decide.plan_motion`), or None. Only pairs that could come within ``p_m`` during
    the period are evaluated exactly (a bound on how far a gap can move in one period —
    ``|Δv| dt + (a_max,ego + a_max,others) dt²/2`` — filters the rest); the result is the same, faster. The
    reported minimum gaps to F and L1 are exact where the pair came that near, and sampled at the period's ends
    (while the ego is in the conflict zone) where it stayed farther. From :data:`FAST_MIN_ROWS` scenarios on (and
    without switches inside the period) it runs the compiled kernel (:mod:`._fast_checks`) where numba imports and
    ``SAFELANE_NO_NUMBA`` is not ``1``: the same bits, the NumPy path below is the reference.
    """
    if others.switch is None and len(lon.x) >= FAST_MIN_ROWS and (kernel := checks_kernel()) is not None:
        return kernel.ego_checks(b, prm, s, lon, lat, others, conflict_level, overlap_level, plan)
    dt = prm.dt
    bsz = len(lon.x)
    planned = np.zeros(bsz, bool)
    y_min, y_max = lateral_extent(ARRAY, lat.x[:, 0], lat.v[:, 0], lat.acc[:, 0], dt)
    x_end, y_end = lon.x[:, -1], lat.x[:, -1]
    if plan is not None and plan[0].size:
        rows, plan_lon, plan_lat = plan
        planned[rows] = True
        y_max[rows] = extrema(plan_lat)[1]
        x_end, y_end = x_end.copy(), y_end.copy()
        x_end[rows], y_end[rows] = plan_lon.x[:, -1], plan_lat.x[:, -1]
    # Per scenario (not batch-wide), so that which pairs count as near — exact minimum gaps — does not depend on
    # the other scenarios of the batch: a cell gives the same table alone and inside a grid.
    threshold = near_threshold(ARRAY, prm.p_m, max(prm.a_x_a, prm.a_x_d) + others.row_max_abs_acc(), dt)
    d0 = s.x - s.ego[0][:, None]
    near = near_pair(ARRAY, b.valid, d0, s.v - s.ego[2][:, None], threshold[:, None], y_max[:, None], conflict_level,
                     dt)  # fmt: skip
    c, r = np.nonzero(near.T)  # the (B, K) masks are column-major: scan them vehicle by vehicle
    collided, violated = np.zeros(bsz, bool), np.zeros(bsz, bool)
    min_gap_f, min_gap_l1 = (
        far_gap(ARRAY, running, b.valid[:, col] & ~near[:, col], sign, d0[:, col], lat.x[:, 0],
                others.x_end[:, col] - x_end, y_end, conflict_level)
        for col, sign, running in ((0, -1.0, s.min_gap_f), (1, 1.0, s.min_gap_l1))
    )  # fmt: skip
    if r.size == 0:
        return collided, violated, min_gap_f, min_gap_l1
    # Pair by pair (the near ones only): (min, max) of the gap over the windows of both lateral levels.
    c_min, c_max, o_min, o_max = (np.empty(r.size) for _ in range(4))
    max_level = max(conflict_level, overlap_level)
    simple, stops = ego_pair_kind(ARRAY, planned[r], lon.t[r, 1], others.t_stop[r, c], y_min[r], max_level, dt)
    if others.switch is not None:  # a switch inside the period: two segments, the general path
        stops &= ~others.switch.mask[r, c]
    ps, pk = np.flatnonzero(simple), np.flatnonzero(stops)
    if pk.size:
        rk, ck = r[pk], c[pk]
        ego = (lon.x[rk, 0], lon.v[rk, 0], lon.acc[rk, 0], lon.t[rk, 1])
        other = (others.x[rk, ck], others.v[rk, ck], others.acc[rk, ck], others.t_stop[rk, ck])
        c_min[pk], c_max[pk] = stop_pair_extrema(ARRAY, *ego, *other, dt)
        o_min[pk], o_max[pk] = c_min[pk], c_max[pk]
    rs, cs = r[ps], c[ps]
    d0 = others.x[rs, cs] - lon.x[rs, 0]
    dv0 = others.v[rs, cs] - lon.v[rs, 0]
    rel_acc = others.acc[rs, cs] - lon.acc[rs, 0]
    lateral = (lat.x[rs, 0], lat.v[rs, 0], lat.acc[rs, 0], y_min[rs])
    for level, lo, hi in ((conflict_level, c_min, c_max), (overlap_level, o_min, o_max)):
        lo[ps], hi[ps] = windowed_quadratic(ARRAY, d0, dv0, rel_acc, *lateral, level, dt)
    general_pairs(r, c, ~simple & ~stops, planned, lon, lat, plan, others, (conflict_level, overlap_level),
                  (c_min, c_max, o_min, o_max), _windowed_general)  # fmt: skip
    apply_pairs(r, c, (c_min, c_max, o_min, o_max), prm, (collided, violated, min_gap_f, min_gap_l1))
    return collided, violated, min_gap_f, min_gap_l1


def _windowed_general(ego_lon: Motion, other: Motion, ego_lat: Motion, level: float):
    """The general path's exact ``(min, max)`` on NumPy: :func:`~.kinematics.windowed_gap_extrema` over the crossings
    of ``level`` (:func:`~.kinematics.crossing_knots`)."""
    return windowed_gap_extrema(ego_lon, other, ego_lat, crossing_knots(ego_lat, level), level)


def general_pairs(r, c, mask, planned, lon, lat, plan, others: Fleet, levels, out, pair_extrema) -> None:
    """The near pairs ``(r, c)[mask]`` left to the general path — an ego on its evasion plan (``plan``'s multi-segment
    motions), or stopping while it crosses a level — their ``(min, max)`` at both ``levels`` written into ``out``
    (``c_min, c_max, o_min, o_max``) by ``pair_extrema(ego_lon, other, ego_lat, level)``: :func:`_windowed_general`
    on NumPy, ``_fast_general``'s kernel from the compiled checks."""
    on_plan = planned[r]
    groups = [(np.flatnonzero(mask & ~on_plan), lon, lat, None)]
    if planned.any():
        rows, plan_lon, plan_lat = plan
        at = np.zeros(len(planned), np.intp)
        at[rows] = np.arange(rows.size)
        groups.append((np.flatnonzero(mask & on_plan), plan_lon, plan_lat, at))
    for level, lo, hi in zip(levels, out[::2], out[1::2], strict=True):
        for pg, m_lon, m_lat, index in groups:
            if pg.size:
                idx = r[pg] if index is None else index[r[pg]]
                lo[pg], hi[pg] = pair_extrema(_rows(m_lon, idx), others.motion(r[pg], c[pg]), _rows(m_lat, idx), level)


def apply_pairs(r, c, extrema_, prm: Params, out) -> None:
    """The near pairs' verdicts (:func:`ego_verdict`) and minimum gaps to F (``c == 0``) and L1 (``c == 1``) folded
    into ``out`` = ``(collided, violated, min_gap_f, min_gap_l1)`` in place; ``extrema_``: the pairs' ``(c_min, c_max,
    o_min, o_max)``."""
    c_min, c_max, o_min, o_max = extrema_
    collided, violated, min_gap_f, min_gap_l1 = out
    hit, close = ego_verdict(ARRAY, c_min, c_max, o_min, o_max, prm.vehicle_length, prm.p_m)
    collided[r[hit]] = True
    violated[r[close]] = True
    f, l1 = c == 0, c == 1  # each (row, vehicle) pair occurs once
    min_gap_f[r[f]] = np.minimum(min_gap_f[r[f]], -c_max[f])
    min_gap_l1[r[l1]] = np.minimum(min_gap_l1[r[l1]], c_min[l1])


def lateral_extent(xp, y0, vy0, ay, dt):
    """Exact ``(min, max)`` over the period of the ego's free lateral motion ``y0 + vy0 t + ay t²/2``
    (:func:`~safelane.shield.decide.lateral_max`, the minimum as the maximum of its mirror). Backend-generic."""
    y_end = y0 + vy0 * dt + 0.5 * ay * dt * dt
    ny0, nvy0, nay = -y0, -vy0, -ay
    return -lateral_max(xp, ny0, nvy0, nay, ny0 + nvy0 * dt + 0.5 * nay * dt * dt, dt), lateral_max(
        xp, y0, vy0, ay, y_end, dt
    )


def near_threshold(xp, p_m, a_bound, dt):
    """How near a pair must start (``|gap|`` less what ``|Δv|`` moves it in a period) to be checked exactly: within
    ``p_m`` plus the most ``a_bound`` (the ego's and the others' largest ``|acceleration|`` together) can move it in
    one period, plus 1 µm. Backend-generic."""
    return p_m + 0.5 * a_bound * dt * dt + 1e-6


def near_pair(xp, valid, d0, dv, threshold, y_max, conflict_level, dt):
    """Whether the ego and a target-lane vehicle (gap ``d0``, speed difference ``dv`` at the period's start) could
    come within ``p_m`` during the period while the ego is in the conflict zone (its lateral maximum ``y_max`` above
    ``conflict_level``): the pairs :func:`ego_checks` evaluates exactly. Backend-generic."""
    return valid & (abs(d0) - abs(dv) * dt < threshold) & (y_max > conflict_level)


def far_gap(xp, running, far, sign, d_start, y_start, d_end, y_end, level):
    """The running minimum gap to F (``sign = −1``) or L1 (``+1``) updated with a pair that stayed far (``far``):
    its gaps ``d_start``/``d_end`` (the vehicle's position less the ego's) sampled at the period's ends where the
    ego is then in the conflict zone (lateral position above ``level``). Backend-generic."""
    g0 = xp.where(y_start > level, sign * d_start, INF)
    g1 = xp.where(y_end > level, sign * d_end, INF)
    return xp.minimum(running, xp.where(far, xp.minimum(g0, g1), INF))


def ego_pair_kind(xp, on_plan, t1, t_stop, y_min, max_level, dt):
    """Which closed form a near pair takes: ``(simple, stops)``. Simple — one quadratic over the period (an ego on a
    constant command that does not stop inside it, ``t1 >= dt``, nor does the other, ``t_stop >= dt``):
    :func:`windowed_quadratic`. Stops — someone stops inside the period while the ego, on a constant command, stays
    laterally beyond both levels all period (``y_min > max_level``: the windows are the whole period):
    :func:`stop_pair_extrema`. Neither — the general path (:func:`general_pairs`). Backend-generic."""
    simple = xp.where(on_plan, False, (t1 >= dt) & (t_stop >= dt))
    return simple, xp.where(on_plan | simple, False, y_min > max_level)


def ego_verdict(xp, c_min, c_max, o_min, o_max, length, p_m):
    """``(collided, violated)`` of a pair from its gap's ``(min, max)`` over the instants the ego overlaps the target
    lane (``o_*``) and is in the conflict zone (``c_*``): footprints overlap, ``|gap| < length``; the margin is
    broken, ``|gap| < p_m`` (to ``DIST_TOL_M``). Backend-generic."""
    return (o_min < length) & (o_max > -length), (c_min < p_m - DIST_TOL_M) & (c_max > -p_m + DIST_TOL_M)


def _stop_gap(xp, t, x1, v1, a1, t1, x2, v2, a2, t2):
    """``x2(t) − x1(t)`` of two motions each at constant acceleration until its knot ``t_i``, at rest after it."""
    return state_at(xp, x2, v2, a2, xp.minimum(t, t2))[0] - state_at(xp, x1, v1, a1, xp.minimum(t, t1))[0]


def _stop_piece(xp, lo, hi, start, end, d_start, d_end, v1, a1, t1, v2, a2, t2):
    """``(lo, hi)`` widened by one piece ``[start, end]`` of :func:`stop_pair_extrema` (one quadratic: who still
    moves is who has not reached its knot at ``start``)."""
    moving1, moving2 = start < t1, start < t2
    dv = xp.where(moving2, v2 + a2 * start, 0.0) - xp.where(moving1, v1 + a1 * start, 0.0)
    acc = xp.where(moving2, a2, 0.0) - xp.where(moving1, a1, 0.0)
    vertex_lo, vertex_hi = vertex_extrema(xp, d_start, dv, acc, end - start)
    return xp.minimum(xp.minimum(lo, d_end), vertex_lo), xp.maximum(xp.maximum(hi, d_end), vertex_hi)


def stop_pair_extrema(xp, x1, v1, a1, t1, x2, v2, a2, t2, dt):
    """Exact ``(min, max)`` over ``[0, dt]`` of ``x2(t) − x1(t)`` for two :meth:`Motion.constant`-type motions:
    each at constant acceleration until its knot ``t_i <= dt`` (a stop inside the period, or ``dt``), at rest
    after it. On the three pieces between ``0``, the two knots and ``dt`` the gap is one quadratic each.
    Backend-generic."""
    k1, k2 = xp.minimum(t1, t2), xp.maximum(t1, t2)
    d0 = _stop_gap(xp, 0.0, x1, v1, a1, t1, x2, v2, a2, t2)
    d1 = _stop_gap(xp, k1, x1, v1, a1, t1, x2, v2, a2, t2)
    d2 = _stop_gap(xp, k2, x1, v1, a1, t1, x2, v2, a2, t2)
    d3 = _stop_gap(xp, dt, x1, v1, a1, t1, x2, v2, a2, t2)
    lo, hi = _stop_piece(xp, xp.minimum(d0, d3), xp.maximum(d0, d3), 0.0, k1, d0, d1, v1, a1, t1, v2, a2, t2)
    lo, hi = _stop_piece(xp, lo, hi, k1, k2, d1, d2, v1, a1, t1, v2, a2, t2)
    return _stop_piece(xp, lo, hi, k2, dt, d2, d3, v1, a1, t1, v2, a2, t2)


def quadratic_extrema(xp, d0, dv0, rel_acc, dt):
    """``(min, max)`` over ``[0, dt]`` of ``d0 + dv0 t + rel_acc t²/2``. Backend-generic."""
    return piece_extrema(xp, d0, dv0, d0 + dv0 * dt + 0.5 * rel_acc * dt * dt, rel_acc, dt)


def windowed_quadratic(xp, d0, dv0, rel_acc, y0, vy0, ay, y_min, level, dt):
    """``(min, max)`` of ``d0 + dv0 t + rel_acc t²/2`` over the instants of ``[0, dt]`` where
    ``y0 + vy0 t + ay t²/2 > level`` — the one-segment case of :func:`~.kinematics.windowed_gap_extrema`, in closed
    form. Where the lateral position stays above ``level`` all period (its minimum ``y_min``, the ego settled in the
    target lane) the window is the whole period; else it is cut by the crossings (:func:`window_crossings`).
    Backend-generic."""
    lo, hi = quadratic_extrema(xp, d0, dv0, rel_acc, dt)
    cut = y_min <= level
    window_lo, window_hi = window_crossings(xp, d0, dv0, rel_acc, y0, vy0, ay, level, dt)
    return xp.where(cut, window_lo, lo), xp.where(cut, window_hi, hi)


def window_crossings(xp, d0, dv0, rel_acc, y0, vy0, ay, level, dt):
    """:func:`windowed_quadratic` where the window is cut by crossings of ``level`` (or empty): the period split at
    the crossings (:func:`~.kinematics.segment_crossings`, sorted by a sorting network: four knots, no NaN), each
    interval counted where the lateral position at its midpoint is above ``level``. Backend-generic."""
    e1, e2 = segment_crossings(xp, 0.0, dt, y0, vy0, ay, level)
    k0, k1, k2, k3 = 0.0, dt, e1, e2
    k1, k2 = xp.minimum(k1, k2), xp.maximum(k1, k2)
    k0, k1 = xp.minimum(k0, k1), xp.maximum(k0, k1)
    k2, k3 = xp.minimum(k2, k3), xp.maximum(k2, k3)
    k1, k2 = xp.minimum(k1, k2), xp.maximum(k1, k2)
    k0, k1 = xp.minimum(k0, k1), xp.maximum(k0, k1)
    k2, k3 = xp.minimum(k2, k3), xp.maximum(k2, k3)
    vertex_t = xp.div(-dv0, rel_acc, -1.0)
    lo0, hi0 = _window_interval(xp, d0, dv0, rel_acc, y0, vy0, ay, level, k0, k1, vertex_t)
    lo1, hi1 = _window_interval(xp, d0, dv0, rel_acc, y0, vy0, ay, level, k1, k2, vertex_t)
    lo2, hi2 = _window_interval(xp, d0, dv0, rel_acc, y0, vy0, ay, level, k2, k3, vertex_t)
    return xp.minimum(xp.minimum(lo0, lo1), lo2), xp.maximum(xp.maximum(hi0, hi1), hi2)


def _window_interval(xp, d0, dv0, rel_acc, y0, vy0, ay, level, tau0, tau1, vertex_t):
    """One interval ``[tau0, tau1]`` of :func:`window_crossings`: the gap's ``(min, max)`` there (its ends, and its
    vertex at ``vertex_t`` where that lies strictly inside), ``(inf, −inf)`` where the ego is not above ``level``."""
    mid = 0.5 * (tau0 + tau1)
    active = state_at(xp, y0, vy0, ay, mid)[0] > level
    d_a, d_b = state_at(xp, d0, dv0, rel_acc, tau0)[0], state_at(xp, d0, dv0, rel_acc, tau1)[0]
    vertex = state_at(xp, d0, dv0, rel_acc, vertex_t)[0]
    inside = (vertex_t > tau0) & (vertex_t < tau1)
    lo = xp.where(inside & (rel_acc > 0.0), xp.minimum(xp.minimum(d_a, d_b), vertex), xp.minimum(d_a, d_b))
    hi = xp.where(inside & (rel_acc < 0.0), xp.maximum(xp.maximum(d_a, d_b), vertex), xp.maximum(d_a, d_b))
    return xp.where(active, lo, INF), xp.where(active, hi, -INF)


def lane_pairs(b, prm: Params):
    """Constant inputs of :func:`lane_checks`: ``(valid, margin)`` of each consecutive pair, ``(B, K−1)``."""
    return b.valid[:, 1:] & b.valid[:, :-1], np.where(b.human[:, :-1], prm.p_m_human, prm.p_m)


def lane_checks(b, prm: Params, others: Fleet, pairs=None):
    """Exact collision / margin checks between consecutive target-lane vehicles (F–L1, L1–L2, …), and each
    scenario's smallest ``gap / margin`` over its pairs this period (exact where a pair came near its margin,
    sampled at the period's ends elsewhere; ``inf`` without valid pairs).

    Only pairs whose gap could come within the margin during the period are evaluated exactly: a gap moves by at
    most ``|Δv| dt + a_max dt²`` in a period, with ``a_max`` the scenario's largest ``|acceleration|`` (per scenario,
    so that the result does not depend on the batch). ``pairs``: :func:`lane_pairs` (computed here unless given).
    Returns ``(collided, violated, min_ratio)``.
    """
    dt = prm.dt
    valid, margin = pairs if pairs is not None else lane_pairs(b, prm)
    if others.switch is None and len(others.x) >= FAST_MIN_ROWS and (kernel := checks_kernel()) is not None:
        return kernel.lane_checks(prm, others, (valid, margin))  # compiled, the same bits (_fast_checks)
    x0, v0, xe, ve = others.x, others.v, others.x_end, others.v_end
    near = lane_near(ARRAY, valid, x0[:, :-1], v0[:, :-1], xe[:, :-1], ve[:, :-1], x0[:, 1:], v0[:, 1:], xe[:, 1:],
                     ve[:, 1:], margin, others.row_max_abs_acc()[:, None], dt)  # fmt: skip
    sampled = lane_far_ratio(ARRAY, valid & ~near, x0[:, 1:] - x0[:, :-1], xe[:, 1:] - xe[:, :-1], margin)
    c, r = np.nonzero(near.T)  # the (B, K) masks are column-major: scan them vehicle by vehicle
    bsz = len(x0)
    collided, violated = np.zeros(bsz, bool), np.zeros(bsz, bool)
    min_ratio = sampled.min(1, initial=np.inf)
    if r.size == 0:
        return collided, violated, min_ratio
    pair_min = np.empty(r.size)
    one = others.t_stop >= dt
    simple = one[r, c] & one[r, c + 1]
    two = np.zeros(r.size, bool)
    if others.switch is not None:  # a switch inside the period: exact over the merged knots of both motions
        two = others.switch.mask[r, c] | others.switch.mask[r, c + 1]
        pt = np.flatnonzero(two)
        if pt.size:
            pair_min[pt] = gap_extrema(others.motion(r[pt], c[pt]), others.motion(r[pt], c[pt] + 1))[0]
    ps, pg = np.flatnonzero(simple & ~two), np.flatnonzero(~simple & ~two)
    rs, cs, rg, cg = r[ps], c[ps], r[pg], c[pg]
    d0 = x0[rs, cs + 1] - x0[rs, cs]
    dv0 = v0[rs, cs + 1] - v0[rs, cs]
    rel_acc = others.acc[rs, cs + 1] - others.acc[rs, cs]
    pair_min[ps] = quadratic_extrema(ARRAY, d0, dv0, rel_acc, dt)[0]
    if pg.size:  # someone stops inside the period: closed form over the stop knots
        behind = (others.x[rg, cg], others.v[rg, cg], others.acc[rg, cg], others.t_stop[rg, cg])
        ahead = (others.x[rg, cg + 1], others.v[rg, cg + 1], others.acc[rg, cg + 1], others.t_stop[rg, cg + 1])
        pair_min[pg], _ = stop_pair_extrema(ARRAY, *behind, *ahead, dt)
    hit, close, ratio = lane_verdict(ARRAY, pair_min, margin[r, c], prm.vehicle_length)
    collided[r[hit]] = True
    violated[r[close]] = True
    np.minimum.at(min_ratio, r, ratio)
    return collided, violated, min_ratio


def lane_near(xp, valid, x0, v0, xe0, ve0, x1, v1, xe1, ve1, margin, a_max, dt):
    """Whether a consecutive target-lane pair (behind: ``x0, v0`` at the start, ``xe0, ve0`` at the end; ahead: the
    same with 1) is checked exactly: its gap less what ``|Δv|`` moves it in a period could come within ``margin``
    plus ``a_max dt²`` (``a_max``: the scenario's largest ``|acceleration|``) and 1 µm — unless both rest all period
    (the gap stays, exact at the period's ends) at or beyond the margin. At rest at both ends is not enough: a switch
    can start and stop a vehicle in between. Backend-generic."""
    gap0 = x1 - x0
    near = valid & (gap0 - abs(v1 - v0) * dt < margin + (a_max * dt * dt + 1e-6))
    resting = (ve0 == 0.0) & (v0 == 0.0) & (xe0 == x0) & (ve1 == 0.0) & (v1 == 0.0) & (xe1 == x1)
    return near & xp.where(resting & (gap0 >= margin), False, True)


def lane_far_ratio(xp, far, gap0, gap1, margin):
    """A far pair's ``gap / margin``, sampled at the period's ends (``inf`` for the others). Backend-generic."""
    return xp.where(far, xp.minimum(gap0, gap1) / margin, INF)


def lane_verdict(xp, low, margin, length):
    """``(collided, violated, ratio)`` of a near pair from its gap's exact minimum ``low``. Backend-generic."""
    return low < length, low < margin - DIST_TOL_M, low / margin


# The rules per pair, compiled into the checks' kernels and the compiled closed loop (safety/_compile.py).
jitable(lateral_extent, near_threshold, near_pair, far_gap, ego_pair_kind, ego_verdict, _stop_gap, _stop_piece,
        stop_pair_extrema, quadratic_extrema, windowed_quadratic, window_crossings, _window_interval, lane_near,
        lane_far_ratio, lane_verdict)  # fmt: skip
