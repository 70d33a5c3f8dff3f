"""Optional compiled kernel of the ego's collision checks (:func:`~.checks.ego_checks`; numba, extra ``fast``).

:func:`ego_kernel` is ``ego_checks`` per scenario and target-lane vehicle: the near-pair filter, the running minimum
gaps of the pairs that stayed far, and the exact gap extrema of the near pairs of the two common kinds — one
quadratic over the whole period, windowed by the ego's lateral crossings of the conflict and overlap levels
(``_windowed_quadratic``), and a vehicle stopping inside the period while the ego stays beyond both levels
(``stop_pair_extrema``). The remaining near pairs — an ego executing an evasion plan (several segments), or stopping
while it crosses a level — are marked, and the wrapper runs the general path (``windowed_gap_extrema``) on those
pairs alone, as ``ego_checks`` does, through :mod:`._fast_general`'s kernel. Every expression is in the NumPy path's
evaluation order, so collisions, violations and minimum gaps are its bits (``tests/test_fast_checks.py``); the NumPy
function stays the reference and the fallback (a fleet with switches inside the period, ``SAFELANE_NO_NUMBA=1``,
numba missing, small batches).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types

from ..params import Params
from ..safety._fast_base import (
    _max,
    _min,
    announce_compile,
    row_function,
)
from ._fast_general import _general
from .checks import _rows
from .kinematics import extrema

announce_compile(__file__)

_INF = np.inf
_M = types.Array(types.float64, 2, "A", readonly=True)
_MB = types.Array(types.bool_, 2, "A", readonly=True)
_V = types.Array(types.float64, 1, "A", readonly=True)
_VB = types.Array(types.bool_, 1, "A", readonly=True)
_OUT_V = types.Array(types.float64, 1, "C")
_OUT_B = types.Array(types.bool_, 1, "C")
_SIGNATURE = types.void(
    _MB, _M, _M, _V, _V,  # valid, s.x, s.v, ego x and vx at the period's start
    _V, _V, _V, _V, _V,  # lon: x0, v0, acc0, stop knot, end position
    _V, _V, _V, _V,  # lat: y0, vy0, ay0, end position
    _VB, _V, _V, _V,  # planned rows: their y_max, end x, end y
    _M, _M, _M, _M, _M, _V,  # others: x, v, acc, t_stop, x_end; each row's largest |acc|
    *(types.float64,) * 7,  # dt, p_m, max(a_x_a, a_x_d), conflict level, overlap level, vehicle length, max level
    _OUT_B, _OUT_B, _OUT_V, _OUT_V, types.Array(types.bool_, 2, "F"),
)  # fmt: skip


@numba.njit(inline="always")
def _free_max(y0, vy0, a, dt):  # _motion.free_max
    end = y0 + vy0 * dt + 0.5 * a * dt * dt
    tau = -vy0 / a if a < 0.0 else -1.0
    vertex = y0 + 0.5 * vy0 * tau if (tau > 0.0 and tau < dt) else -_INF
    return _max(_max(y0, end), vertex)


@numba.njit(inline="always")
def _quadratic_extrema(d0, dv0, ra, dt):  # checks._quadratic_extrema
    end = d0 + dv0 * dt + 0.5 * ra * dt * dt
    tau = -dv0 / ra if ra != 0.0 else -1.0
    inside = tau > 0.0 and tau < dt
    vertex = d0 + dv0 * tau + 0.5 * ra * tau * tau
    lo = _min(_min(d0, end), vertex if (inside and ra > 0.0) else _INF)
    hi = _max(_max(d0, end), vertex if (inside and ra < 0.0) else -_INF)
    return lo, hi


@numba.njit(error_model="numpy", nogil=True)
def _quadratic(d0, dv0, ra, y0, vy0, ay, level, dt):  # checks._windowed_quadratic
    lo, hi = _quadratic_extrema(d0, dv0, ra, dt)
    if not -_free_max(-y0, -vy0, -ay, dt) <= level:
        return lo, hi
    # checks._window_crossings: the window cut by the lateral crossings of the level (kinematics.crossing_knots)
    yy = y0 - level
    disc = vy0 * vy0 - 2.0 * ay * yy
    root = np.sqrt(_max(disc, 0.0))
    quad = ay != 0.0 and disc >= 0.0
    safe_a = ay if ay != 0.0 else 1.0
    if quad:
        r1 = (-vy0 - root) / safe_a
        r2 = (-vy0 + root) / safe_a
    else:
        r1 = -yy / (vy0 if vy0 != 0.0 else 1.0) if (ay == 0.0 and vy0 != 0.0) else -1.0
        r2 = -1.0
    e1 = 0.0 + r1 if (r1 > 0.0 and r1 < dt) else 0.0
    e2 = 0.0 + r2 if (r2 > 0.0 and r2 < dt) else 0.0
    # sort the knots 0, dt, e1, e2 (no NaN): a sorting network
    k0, k1, k2, k3 = 0.0, dt, e1, e2
    if k1 > k2:
        k1, k2 = k2, k1
    if k0 > k1:
        k0, k1 = k1, k0
    if k2 > k3:
        k2, k3 = k3, k2
    if k1 > k2:
        k1, k2 = k2, k1
    if k0 > k1:
        k0, k1 = k1, k0
    if k2 > k3:
        k2, k3 = k3, k2
    vertex_t = -dv0 / ra if ra != 0.0 else -1.0
    lo_all, hi_all = _INF, -_INF
    for j in range(3):
        tau0 = k0 if j == 0 else (k1 if j == 1 else k2)
        tau1 = k1 if j == 0 else (k2 if j == 1 else k3)
        mid = 0.5 * (tau0 + tau1)
        if not y0 + vy0 * mid + 0.5 * ay * mid * mid > level:
            continue
        da = d0 + dv0 * tau0 + 0.5 * ra * tau0 * tau0
        db = d0 + dv0 * tau1 + 0.5 * ra * tau1 * tau1
        lo, hi = _min(da, db), _max(da, db)
        if vertex_t > tau0 and vertex_t < tau1:
            vertex = d0 + dv0 * vertex_t + 0.5 * ra * vertex_t * vertex_t
            if ra > 0.0:
                lo = _min(lo, vertex)
            if ra < 0.0:
                hi = _max(hi, vertex)
        lo_all, hi_all = _min(lo_all, lo), _max(hi_all, hi)
    return lo_all, hi_all


@numba.njit(inline="always")
def _gap_at(t, x1, v1, a1, t1, x2, v2, a2, t2):  # stop_pair_extrema's gap(t)
    m1, m2 = _min(t, t1), _min(t, t2)
    return (x2 + v2 * m2 + 0.5 * a2 * m2 * m2) - (x1 + v1 * m1 + 0.5 * a1 * m1 * m1)


@numba.njit(error_model="numpy", nogil=True)
def _stop_pair(x1, v1, a1, t1, x2, v2, a2, t2, dt):  # checks.stop_pair_extrema: (min, max) of x2(t) - x1(t)
    knots = (0.0, _min(t1, t2), _max(t1, t2), dt)
    d = (
        _gap_at(knots[0], x1, v1, a1, t1, x2, v2, a2, t2),
        _gap_at(knots[1], x1, v1, a1, t1, x2, v2, a2, t2),
        _gap_at(knots[2], x1, v1, a1, t1, x2, v2, a2, t2),
        _gap_at(knots[3], x1, v1, a1, t1, x2, v2, a2, t2),
    )
    lo, hi = _min(d[0], d[3]), _max(d[0], d[3])
    for j in range(3):  # the three pieces between the knots, one quadratic each
        start, end = knots[j], knots[j + 1]
        moving1, moving2 = start < t1, start < t2
        dv = (v2 + a2 * start if moving2 else 0.0) - (v1 + a1 * start if moving1 else 0.0)
        acc = (a2 if moving2 else 0.0) - (a1 if moving1 else 0.0)
        tau = -dv / acc
        inside = tau > 0.0 and tau < end - start
        vertex = d[j] + dv * tau + 0.5 * acc * tau * tau
        lo = _min(_min(lo, d[j + 1]), vertex if (inside and acc > 0.0) else _INF)
        hi = _max(_max(hi, d[j + 1]), vertex if (inside and acc < 0.0) else -_INF)
    return lo, hi


@row_function
def _ego_row(valid, vb, sx, sv, r, ego, lon, lat, plan, fleet, row_acc, consts, gaps, general):
    """One scenario of :func:`ego_kernel`: row ``vb`` of ``valid``, row ``r`` of the vehicles' arrays (``sx``, ``sv``,
    ``fleet``'s, ``general``; 2-D, indexed in place: a row view or an out-of-line call with arrays costs more than
    the row's arithmetic: ``_fast_base.row_function``). ``ego``: ``(x, vx)`` at the start; ``lon``: ``(x0, v0,
    acc0, t1, x_end)``; ``lat``: ``(y0, vy0, ay0, y_end)``; ``plan``: ``(on_plan, y_max, x_end, y_end)``; ``fleet``:
    ``(x, v, acc, t_stop, x_end)``; ``consts``: ``(dt, p_m, a_lim, conflict, overlap, length, max_level)``;
    ``gaps``: the running ``(gap_f, gap_l1)``. Returns ``(collided, violated, gap_f, gap_l1)``; ``general[r, c]``
    marks the pairs left to the general path."""
    ego_x, ego_vx = ego
    x0, v0, acc0, t1, x_end = lon
    y0, vy0, ay0, y_end = lat
    on_plan, plan_y_max, plan_x_end, plan_y_end = plan
    ox, ov, oacc, ots, ox_end = fleet
    dt, p_m, a_lim, conflict, overlap, length, max_level = consts
    gap_f, gap_l1 = gaps
    if on_plan:
        y_max, xe, ye = plan_y_max, plan_x_end, plan_y_end
    else:
        y_max, xe, ye = _free_max(y0, vy0, ay0, dt), x_end, y_end
    settled = (not on_plan) and -_free_max(-y0, -vy0, -ay0, dt) > max_level
    threshold = p_m + 0.5 * (a_lim + row_acc) * dt * dt + 1e-6
    in_zone = y_max > conflict
    hit, close = False, False
    for c in range(sx.shape[1]):
        d0 = sx[r, c] - ego_x
        near = valid[vb, c] and (abs(d0) - abs(sv[r, c] - ego_vx) * dt < threshold) and in_zone
        if not near:
            if c < 2 and valid[vb, c]:  # checks._far_gaps: sampled at the period's ends in the conflict zone
                sign = -1.0 if c == 0 else 1.0
                g0 = sign * d0 if y0 > conflict else _INF
                g1 = sign * (ox_end[r, c] - xe) if ye > conflict else _INF
                if c == 0:
                    gap_f = _min(gap_f, _min(g0, g1))
                else:
                    gap_l1 = _min(gap_l1, _min(g0, g1))
            continue
        if (not on_plan) and t1 >= dt and ots[r, c] >= dt:  # one quadratic over the period
            dd, dv, ra = ox[r, c] - x0, ov[r, c] - v0, oacc[r, c] - acc0
            c_min, c_max = _quadratic(dd, dv, ra, y0, vy0, ay0, conflict, dt)
            o_min, o_max = _quadratic(dd, dv, ra, y0, vy0, ay0, overlap, dt)
        elif settled:  # someone stops inside the period, the ego beyond both levels all period
            c_min, c_max = _stop_pair(x0, v0, acc0, t1, ox[r, c], ov[r, c], oacc[r, c], ots[r, c], dt)
            o_min, o_max = c_min, c_max
        else:
            general[r, c] = True
            continue
        hit = hit or (o_min < length and o_max > -length)
        close = close or (c_min < p_m - 1e-9 and c_max > -p_m + 1e-9)
        if c == 0:
            gap_f = _min(gap_f, -c_max)
        elif c == 1:
            gap_l1 = _min(gap_l1, c_min)
    return hit, close, gap_f, gap_l1


@numba.njit(_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def ego_kernel(
    valid, sx, sv, ego_x, ego_vx, x0, v0, acc0, t1, x_end, y0, vy0, ay0, y_end, planned, plan_y_max, plan_x_end,
    plan_y_end, ox, ov, oacc, ots, ox_end, row_acc, dt, p_m, a_lim, conflict, overlap, length, max_level, collided,
    violated, min_gap_f, min_gap_l1, general,
):  # fmt: skip
    """Per scenario ``b``: ``collided[b]``, ``violated[b]``, the running ``min_gap_f[b]``/``min_gap_l1[b]`` (updated
    in place) over the far pairs and the near pairs of the two common kinds; ``general[b, c]`` marks the near pairs
    left to the exact general path."""
    fleet = (ox, ov, oacc, ots, ox_end)
    consts = (dt, p_m, a_lim, conflict, overlap, length, max_level)
    for b in range(sx.shape[0]):
        collided[b], violated[b], min_gap_f[b], min_gap_l1[b] = _ego_row(
            valid, b, sx, sv, b, (ego_x[b], ego_vx[b]), (x0[b], v0[b], acc0[b], t1[b], x_end[b]),
            (y0[b], vy0[b], ay0[b], y_end[b]), (planned[b], plan_y_max[b], plan_x_end[b], plan_y_end[b]), fleet,
            row_acc[b], consts, (min_gap_f[b], min_gap_l1[b]), general,
        )  # fmt: skip


def ego_checks(b, prm: Params, s, lon, lat, others, conflict_level: float, overlap_level: float, plan=None):
    """:func:`~.checks.ego_checks` through :func:`ego_kernel`, the general pairs through NumPy's exact path."""
    dt = prm.dt
    bsz = len(lon.x)
    planned = np.zeros(bsz, bool)
    plan_y_max, plan_x_end, plan_y_end = (np.zeros(bsz) for _ in range(3))
    at = None
    if plan is not None and plan[0].size:
        rows, plan_lon, plan_lat = plan
        planned[rows] = True
        at = np.zeros(bsz, np.intp)
        at[rows] = np.arange(rows.size)
        plan_y_max[rows] = extrema(plan_lat)[1]
        plan_x_end[rows], plan_y_end[rows] = plan_lon.x[:, -1], plan_lat.x[:, -1]
    collided, violated = np.empty(bsz, bool), np.empty(bsz, bool)
    min_gap_f, min_gap_l1 = s.min_gap_f.astype(np.float64, copy=True), s.min_gap_l1.astype(np.float64, copy=True)
    general = np.zeros(s.x.shape, bool, order="F")
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    ego_kernel(
        b.valid, s.x, s.v, s.ego[0], s.ego[2], f(lon.x[:, 0]), f(lon.v[:, 0]), f(lon.acc[:, 0]), f(lon.t[:, 1]),
        f(lon.x[:, -1]), f(lat.x[:, 0]), f(lat.v[:, 0]), f(lat.acc[:, 0]), f(lat.x[:, -1]), planned, plan_y_max,
        plan_x_end, plan_y_end, others.x, others.v, others.acc, others.t_stop, others.x_end, others.row_max_abs_acc(),
        dt, prm.p_m, max(prm.a_x_a, prm.a_x_d), conflict_level, overlap_level, prm.vehicle_length,
        max(conflict_level, overlap_level), collided, violated, min_gap_f, min_gap_l1, general,
    )  # fmt: skip
    c, r = np.nonzero(general.T)
    if r.size:  # the exact general path (ego_checks' own) on the pairs the kernel left
        c_min, c_max, o_min, o_max = (np.empty(r.size) for _ in range(4))
        on_plan = planned[r]
        groups = [(np.flatnonzero(~on_plan), lon, lat, None)]
        if planned.any():
            groups.append((np.flatnonzero(on_plan), plan_lon, plan_lat, at))
        for level, lo, hi in ((conflict_level, c_min, c_max), (overlap_level, o_min, o_max)):
            for pg, m_lon, m_lat, index in groups:
                if pg.size:
                    idx = r[pg] if index is None else index[r[pg]]
                    lo[pg], hi[pg] = _general(_rows(m_lon, idx), others.motion(r[pg], c[pg]), _rows(m_lat, idx), level)
        length = prm.vehicle_length
        collided[r[(o_min < length) & (o_max > -length)]] = True
        violated[r[(c_min < prm.p_m - 1e-9) & (c_max > -prm.p_m + 1e-9)]] = True
        f0, l1 = c == 0, c == 1
        min_gap_f[r[f0]] = np.minimum(min_gap_f[r[f0]], -c_max[f0])
        min_gap_l1[r[l1]] = np.minimum(min_gap_l1[r[l1]], c_min[l1])
    return collided, violated, min_gap_f, min_gap_l1


_LANE_SIGNATURE = types.void(_MB, _M, _M, _M, _M, _M, _M, _M, _V, types.float64, types.float64, _OUT_B, _OUT_B, _OUT_V)


@row_function
def _lane_row(valid, margin, pb, x, v, acc, t_stop, x_end, v_end, r, row_acc, dt, length):
    """One scenario of :func:`lane_kernel`: row ``pb`` of the pairs' ``valid``/``margin`` (``(., K-1)``), row ``r``
    of the vehicles' arrays (indexed in place, as :func:`_ego_row`). Returns ``(collided, violated, min_ratio)``."""
    slack = row_acc * dt * dt + 1e-6
    ratio = _INF
    hit, close = False, False
    for c in range(x.shape[1] - 1):
        if not valid[pb, c]:
            continue
        m = margin[pb, c]
        gap0 = x[r, c + 1] - x[r, c]
        near = gap0 - abs(v[r, c + 1] - v[r, c]) * dt < m + slack
        if near and gap0 >= m:  # both at rest all period keep their gap: no exact check needed
            rest0 = v_end[r, c] == 0.0 and v[r, c] == 0.0 and x_end[r, c] == x[r, c]
            rest1 = v_end[r, c + 1] == 0.0 and v[r, c + 1] == 0.0 and x_end[r, c + 1] == x[r, c + 1]
            near = not (rest0 and rest1)
        if not near:
            ratio = _min(ratio, _min(gap0, x_end[r, c + 1] - x_end[r, c]) / m)
            continue
        if t_stop[r, c] >= dt and t_stop[r, c + 1] >= dt:
            low = _quadratic_extrema(gap0, v[r, c + 1] - v[r, c], acc[r, c + 1] - acc[r, c], dt)[0]
        else:
            low = _stop_pair(x[r, c], v[r, c], acc[r, c], t_stop[r, c], x[r, c + 1], v[r, c + 1], acc[r, c + 1],
                             t_stop[r, c + 1], dt)[0]  # fmt: skip
        hit = hit or low < length
        close = close or low < m - 1e-9
        ratio = _min(ratio, low / m)
    return hit, close, ratio


@numba.njit(_LANE_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def lane_kernel(valid, margin, x, v, acc, t_stop, x_end, v_end, row_acc, dt, length, collided, violated, min_ratio):
    """:func:`~.checks.lane_checks` per scenario and consecutive pair (``valid``/``margin`` ``(B, K-1)``): the
    near-pair filter, the sampled ratios of the far pairs, the exact minimum of the near ones (one quadratic, or
    ``stop_pair_extrema`` where one of the two stops inside the period)."""
    for b in range(x.shape[0]):
        collided[b], violated[b], min_ratio[b] = _lane_row(valid, margin, b, x, v, acc, t_stop, x_end, v_end, b,
                                                           row_acc[b], dt, length)  # fmt: skip


def lane_checks(prm: Params, others, pairs):
    """:func:`~.checks.lane_checks` through :func:`lane_kernel` (a fleet without switches)."""
    valid, margin = pairs
    bsz = len(others.x)
    collided, violated, min_ratio = np.empty(bsz, bool), np.empty(bsz, bool), np.empty(bsz)
    lane_kernel(
        valid, np.asarray(margin, dtype=np.float64), others.x, others.v, others.acc, others.t_stop, others.x_end,
        others.v_end, others.row_max_abs_acc(), prm.dt, prm.vehicle_length, collided, violated, min_ratio,
    )  # fmt: skip
    return collided, violated, min_ratio
