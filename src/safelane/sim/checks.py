"""Exact per-period safety bookkeeping: ego collisions / p_m violations and target-lane pair checks.

Collisions are physical overlap of footprints (longitudinal ``|dx| < vehicle_length`` at an instant when the
ego overlaps the target lane laterally); violations are ``|dx| < p_m`` at an instant when the ego is in the
conflict zone. Both are evaluated in continuous time within the period.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..safety.evasion import fast_kernel
from .kinematics import Fleet, Motion, crossing_knots, extrema, free_max, gap_extrema, windowed_gap_extrema


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
    max_level = max(conflict_level, overlap_level)
    planned = np.zeros(bsz, bool)
    y_max = free_max(lat.x[:, 0], lat.v[:, 0], lat.acc[:, 0], dt)
    x_end, y_end = lon.x[:, -1], lat.x[:, -1]
    if plan is not None and plan[0].size:
        rows, plan_lon, plan_lat = plan
        planned[rows] = True
        at = np.zeros(bsz, np.intp)
        at[rows] = np.arange(rows.size)
        y_max[rows] = extrema(plan_lat)[1]
        x_end, y_end = x_end.copy(), y_end.copy()
        x_end[rows], y_end[rows] = plan_lon.x[:, -1], plan_lat.x[:, -1]
    d0 = s.x - s.ego[0][:, None]
    # Per scenario (not batch-wide), so that which pairs count as near — exact minimum gaps — does not depend on
    # the other scenarios of the batch: a cell gives the same table alone and inside a grid.
    a_bound = (max(prm.a_x_a, prm.a_x_d) + others.row_max_abs_acc())[:, None]
    reach = np.abs(s.v - s.ego[2][:, None]) * dt
    near = b.valid & (np.abs(d0) - reach < prm.p_m + 0.5 * a_bound * dt * dt + 1e-6) & (y_max > conflict_level)[:, None]
    c, r = np.nonzero(near.T)  # the (B, K) masks are column-major: scan them vehicle by vehicle
    collided, violated = np.zeros(bsz, bool), np.zeros(bsz, bool)
    min_gap_f, min_gap_l1 = _far_gaps(b, s, lat.x[:, 0], x_end, y_end, others, near, conflict_level)
    if r.size == 0:
        return collided, violated, min_gap_f, min_gap_l1
    # Pair by pair (the near ones only): (min, max) of the gap over the windows of both lateral levels.
    c_min, c_max, o_min, o_max = (np.empty(r.size) for _ in range(4))
    # Most pairs are one quadratic over the whole period (nobody stops or switches inside it): closed form.
    on_plan = planned[r]
    simple = ~on_plan & (lon.t[r, 1] >= dt) & (others.t_stop[r, c] >= dt)
    # Next most: someone stops inside the period while the ego, on a constant command, stays laterally beyond
    # both levels all period (the windows are the whole period): closed form over the stop knots.
    settled = ~planned & (-free_max(-lat.x[:, 0], -lat.v[:, 0], -lat.acc[:, 0], dt) > max_level)
    stops = ~simple & settled[r]
    if others.switch is not None:  # a switch inside the period: two segments, the general path
        stops &= ~others.switch.mask[r, c]
    ps, pk = np.flatnonzero(simple), np.flatnonzero(stops)
    rest = ~simple & ~stops
    general = [(np.flatnonzero(rest & ~on_plan), lon, lat, None)]
    if planned.any():
        general.append((np.flatnonzero(rest & on_plan), plan_lon, plan_lat, at))
    if pk.size:
        rk, ck = r[pk], c[pk]
        ego = (lon.x[rk, 0], lon.v[rk, 0], lon.acc[rk, 0], lon.t[rk, 1])
        other = (others.x[rk, ck], others.v[rk, ck], others.acc[rk, ck], others.t_stop[rk, ck])
        c_min[pk], c_max[pk] = stop_pair_extrema(*ego, *other, dt)
        o_min[pk], o_max[pk] = c_min[pk], c_max[pk]
    rs, cs = r[ps], c[ps]
    d0 = others.x[rs, cs] - lon.x[rs, 0]
    dv0 = others.v[rs, cs] - lon.v[rs, 0]
    rel_acc = others.acc[rs, cs] - lon.acc[rs, 0]
    lateral = (lat.x[rs, 0], lat.v[rs, 0], lat.acc[rs, 0])
    for level, lo, hi in ((conflict_level, c_min, c_max), (overlap_level, o_min, o_max)):
        lo[ps], hi[ps] = _windowed_quadratic(d0, dv0, rel_acc, *lateral, level, dt)
        for pg, m_lon, m_lat, index in general:
            if pg.size:
                idx = r[pg] if index is None else index[r[pg]]
                ego_lon, ego_lat = _rows(m_lon, idx), _rows(m_lat, idx)
                knots = crossing_knots(ego_lat, level)
                lo[pg], hi[pg] = windowed_gap_extrema(ego_lon, others.motion(r[pg], c[pg]), ego_lat, knots, level)
    length = prm.vehicle_length
    collided[r[(o_min < length) & (o_max > -length)]] = True
    violated[r[(c_min < prm.p_m - 1e-9) & (c_max > -prm.p_m + 1e-9)]] = True
    f, l1 = c == 0, c == 1  # each (row, vehicle) pair occurs once
    min_gap_f[r[f]] = np.minimum(min_gap_f[r[f]], -c_max[f])
    min_gap_l1[r[l1]] = np.minimum(min_gap_l1[r[l1]], c_min[l1])
    return collided, violated, min_gap_f, min_gap_l1


def _far_gaps(b, s, y_start, x_end, y_end, others: Fleet, near, level: float):
    """The running minimum gaps to F and L1 updated with the pairs that stayed far this period, sampled at the
    period's ends where the ego is in the conflict zone (the near pairs are added exactly afterwards)."""
    out = []
    for col, sign, running in ((0, -1.0, s.min_gap_f), (1, 1.0, s.min_gap_l1)):
        far = b.valid[:, col] & ~near[:, col]
        g0 = np.where(far & (y_start > level), sign * (s.x[:, col] - s.ego[0]), np.inf)
        g1 = np.where(far & (y_end > level), sign * (others.x_end[:, col] - x_end), np.inf)
        out.append(np.minimum(running, np.minimum(g0, g1)))
    return out


def stop_pair_extrema(x1, v1, a1, t1, x2, v2, a2, t2, dt: float):
    """Exact ``(min, max)`` over ``[0, dt]`` of ``x2(t) − x1(t)`` for two :meth:`Motion.constant`-type motions:
    each at constant acceleration until its knot ``t_i <= dt`` (a stop inside the period, or ``dt``), at rest
    after it. On the three pieces between ``0``, the two knots and ``dt`` the gap is one quadratic each."""
    knots = (np.zeros_like(t1), np.minimum(t1, t2), np.maximum(t1, t2), np.full_like(t1, dt))

    def gap(t):
        m1, m2 = np.minimum(t, t1), np.minimum(t, t2)
        return (x2 + v2 * m2 + 0.5 * a2 * m2 * m2) - (x1 + v1 * m1 + 0.5 * a1 * m1 * m1)

    d = [gap(k) for k in knots]
    lo, hi = np.minimum(d[0], d[3]), np.maximum(d[0], d[3])
    with np.errstate(all="ignore"):
        for start, end, d_start, d_end in zip(knots[:-1], knots[1:], d[:-1], d[1:], strict=True):
            moving1, moving2 = start < t1, start < t2
            dv = np.where(moving2, v2 + a2 * start, 0.0) - np.where(moving1, v1 + a1 * start, 0.0)
            acc = np.where(moving2, a2, 0.0) - np.where(moving1, a1, 0.0)
            tau = -dv / acc
            inside = (tau > 0.0) & (tau < end - start)
            vertex = d_start + dv * tau + 0.5 * acc * tau * tau
            lo = np.minimum(np.minimum(lo, d_end), np.where(inside & (acc > 0.0), vertex, np.inf))
            hi = np.maximum(np.maximum(hi, d_end), np.where(inside & (acc < 0.0), vertex, -np.inf))
    return lo, hi


def _quadratic_extrema(d0, dv0, rel_acc, dt: float):
    """``(min, max)`` over ``[0, dt]`` of ``d0 + dv0 t + rel_acc t²/2``."""
    end = d0 + dv0 * dt + 0.5 * rel_acc * dt * dt
    tau = np.where(rel_acc != 0.0, -dv0 / np.where(rel_acc != 0.0, rel_acc, 1.0), -1.0)
    inside = (tau > 0.0) & (tau < dt)
    vertex = d0 + dv0 * tau + 0.5 * rel_acc * tau * tau
    lo = np.minimum(np.minimum(d0, end), np.where(inside & (rel_acc > 0.0), vertex, np.inf))
    hi = np.maximum(np.maximum(d0, end), np.where(inside & (rel_acc < 0.0), vertex, -np.inf))
    return lo, hi


def _windowed_quadratic(d0, dv0, rel_acc, y0, vy0, ay, level: float, dt: float):
    """``(min, max)`` of ``d0 + dv0 t + rel_acc t²/2`` over the instants of ``[0, dt]`` where
    ``y0 + vy0 t + ay t²/2 > level`` — the one-segment case of :func:`windowed_gap_extrema`, in closed form.
    Where the lateral position stays above ``level`` all period (the ego settled in the target lane) the window
    is the whole period."""
    lo, hi = _quadratic_extrema(d0, dv0, rel_acc, dt)
    part = np.flatnonzero(-free_max(-y0, -vy0, -ay, dt) <= level)
    if part.size:
        sub = (a[part] for a in (d0, dv0, rel_acc, y0, vy0, ay))
        lo[part], hi[part] = _window_crossings(*sub, level, dt)
    return lo, hi


def _window_crossings(d0, dv0, rel_acc, y0, vy0, ay, level: float, dt: float):
    """:func:`_windowed_quadratic` where the window is cut by crossings of ``level`` (or empty)."""
    one = Motion(
        t=np.stack([np.zeros_like(y0), np.full_like(y0, dt)], -1),
        x=np.stack([y0, y0 + vy0 * dt + 0.5 * ay * dt * dt], -1),
        v=np.stack([vy0, vy0 + ay * dt], -1),
        acc=ay[:, None],
    )
    knots = crossing_knots(one, level)  # (P, 4): 0, up to two crossings, dt
    tau0, tau1 = knots[:, :-1], knots[:, 1:]
    mid = 0.5 * (tau0 + tau1)
    active = y0[:, None] + vy0[:, None] * mid + 0.5 * ay[:, None] * mid * mid > level

    def d(t):
        return d0[:, None] + dv0[:, None] * t + 0.5 * rel_acc[:, None] * t * t

    lo, hi = np.minimum(d(tau0), d(tau1)), np.maximum(d(tau0), d(tau1))
    safe = np.where(rel_acc != 0.0, rel_acc, 1.0)
    vertex_t = np.where(rel_acc != 0.0, -dv0 / safe, -1.0)[:, None]
    inside = (vertex_t > tau0) & (vertex_t < tau1)
    vertex = d(vertex_t)
    lo = np.where(inside & (rel_acc[:, None] > 0.0), np.minimum(lo, vertex), lo)
    hi = np.where(inside & (rel_acc[:, None] < 0.0), np.maximum(hi, vertex), hi)
    return np.where(active, lo, np.inf).min(-1), np.where(active, hi, -np.inf).max(-1)


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
    x0, v0 = others.x, others.v
    gap0 = x0[:, 1:] - x0[:, :-1]
    gap1 = others.x_end[:, 1:] - others.x_end[:, :-1]
    slack = (others.row_max_abs_acc() * dt * dt + 1e-6)[:, None]
    near = valid & (gap0 - np.abs(v0[:, 1:] - v0[:, :-1]) * dt < margin + slack)
    # Vehicles at rest all period keep their gap: such a pair at or beyond its margin needs no exact check (its gap
    # at the period's ends is exact). At rest at both ends is not enough: a switch can start and stop it in between.
    resting = (others.v_end == 0.0) & (v0 == 0.0) & (others.x_end == x0)
    near &= ~(resting[:, 1:] & resting[:, :-1] & (gap0 >= margin))
    sampled = np.where(valid & ~near, np.minimum(gap0, gap1) / margin, np.inf)
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
    pair_min[ps] = _quadratic_extrema(d0, dv0, rel_acc, dt)[0]
    if pg.size:  # someone stops inside the period: closed form over the stop knots
        behind = (others.x[rg, cg], others.v[rg, cg], others.acc[rg, cg], others.t_stop[rg, cg])
        ahead = (others.x[rg, cg + 1], others.v[rg, cg + 1], others.acc[rg, cg + 1], others.t_stop[rg, cg + 1])
        pair_min[pg], _ = stop_pair_extrema(*behind, *ahead, dt)
    collided[r[pair_min < prm.vehicle_length]] = True
    violated[r[pair_min < margin[r, c] - 1e-9]] = True
    np.minimum.at(min_ratio, r, pair_min / margin[r, c])
    return collided, violated, min_ratio
