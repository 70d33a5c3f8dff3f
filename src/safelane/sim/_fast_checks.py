"""Optional compiled kernel of the ego's collision checks (:func:`~.checks.ego_checks`; numba, extra ``fast``) and of
the lane checks (:func:`~.checks.lane_checks`): loops and indexing only.

Per scenario and target-lane vehicle, :func:`_ego_row` calls the checks' own rules, compiled as they are
(:mod:`.checks`: :func:`~.checks.near_pair`, :func:`~.checks.far_gap`, :func:`~.checks.ego_pair_kind`,
:func:`~.checks.windowed_quadratic`, :func:`~.checks.stop_pair_extrema`, :func:`~.checks.ego_verdict`), and
:func:`_lane_row` per consecutive pair (:func:`~.checks.lane_near`, :func:`~.checks.quadratic_extrema`, …). The near
pairs of neither common kind — an ego executing an evasion plan (several segments), or stopping while it crosses a
level — are marked, and the wrapper runs them through :mod:`._fast_general`'s kernel, as ``ego_checks`` runs its
general path (:func:`~.checks.general_pairs`). Each rule evaluates every expression as on NumPy arrays, so
collisions, violations and minimum gaps are the NumPy path's bits (``tests/test_fast_checks.py``); the NumPy
function stays the fallback (a fleet with switches inside the period, ``SAFELANE_NO_NUMBA=1``, numba missing, small
batches).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types

from ..params import Params
from ..safety import _compile
from ..safety._backend import INF, SCALAR
from ..safety._fast_base import _min, announce_compiles, kernel, row_function
from ._fast_general import _general, _general_pair
from .checks import (
    apply_pairs,
    ego_pair_kind,
    ego_verdict,
    far_gap,
    general_pairs,
    lane_far_ratio,
    lane_near,
    lane_verdict,
    lateral_extent,
    near_pair,
    near_threshold,
    quadratic_extrema,
    stop_pair_extrema,
    window_crossings,
)
from .kinematics import extrema

_compile.register_rows()
announce_compiles()

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
def _windowed(d0, dv0, rel_acc, y0, vy0, ay, y_min, level, dt):
    """:func:`~.checks.windowed_quadratic` with its ``where`` as a branch: the window's crossings are computed only
    where the ego's lateral minimum is at or below the level (measured: computing both, as the ``where`` does, made
    the ego kernel about a third slower)."""
    if y_min <= level:
        return window_crossings(SCALAR, d0, dv0, rel_acc, y0, vy0, ay, level, dt)
    return quadratic_extrema(SCALAR, d0, dv0, rel_acc, dt)


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
    y_min, y_max = lateral_extent(SCALAR, y0, vy0, ay0, dt)
    xe, ye = x_end, y_end
    if on_plan:
        y_max, xe, ye = plan_y_max, plan_x_end, plan_y_end
    threshold = near_threshold(SCALAR, p_m, a_lim + row_acc, dt)
    hit, close = False, False
    for c in range(sx.shape[1]):
        d0 = sx[r, c] - ego_x
        if not near_pair(SCALAR, valid[vb, c], d0, sv[r, c] - ego_vx, threshold, y_max, conflict, dt):
            if c == 0:
                gap_f = far_gap(SCALAR, gap_f, valid[vb, c], -1.0, d0, y0, ox_end[r, c] - xe, ye, conflict)
            elif c == 1:
                gap_l1 = far_gap(SCALAR, gap_l1, valid[vb, c], 1.0, d0, y0, ox_end[r, c] - xe, ye, conflict)
            continue
        simple, stops = ego_pair_kind(SCALAR, on_plan, t1, ots[r, c], y_min, max_level, dt)
        if simple:
            dd, dv, ra = ox[r, c] - x0, ov[r, c] - v0, oacc[r, c] - acc0
            c_min, c_max = _windowed(dd, dv, ra, y0, vy0, ay0, y_min, conflict, dt)
            o_min, o_max = _windowed(dd, dv, ra, y0, vy0, ay0, y_min, overlap, dt)
        elif stops:
            c_min, c_max = stop_pair_extrema(SCALAR, x0, v0, acc0, t1, ox[r, c], ov[r, c], oacc[r, c], ots[r, c], dt)
            o_min, o_max = c_min, c_max
        else:
            general[r, c] = True
            continue
        pair_hit, pair_close = ego_verdict(SCALAR, c_min, c_max, o_min, o_max, length, p_m)
        hit, close = hit or pair_hit, close or pair_close
        if c == 0:
            gap_f = _min(gap_f, -c_max)
        elif c == 1:
            gap_l1 = _min(gap_l1, c_min)
    return hit, close, gap_f, gap_l1


@kernel(_SIGNATURE)
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
    """:func:`~.checks.ego_checks` through :func:`ego_kernel`, the general pairs through :mod:`._fast_general`'s
    kernel (:func:`~.checks.general_pairs`)."""
    dt = prm.dt
    bsz = len(lon.x)
    planned = np.zeros(bsz, bool)
    plan_y_max, plan_x_end, plan_y_end = (np.zeros(bsz) for _ in range(3))
    if plan is not None and plan[0].size:
        rows, plan_lon, plan_lat = plan
        planned[rows] = True
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
    if r.size:  # the exact general path (ego_checks' own) on the pairs the kernel left, through _fast_general
        out = tuple(np.empty(r.size) for _ in range(4))
        general_pairs(r, c, np.ones(r.size, bool), planned, lon, lat, plan, others, (conflict_level, overlap_level),
                      out, _general)  # fmt: skip
        apply_pairs(r, c, out, prm, (collided, violated, min_gap_f, min_gap_l1))
    return collided, violated, min_gap_f, min_gap_l1


_LANE_SIGNATURE = types.void(_MB, _M, _M, _M, _M, _M, _M, _M, _V, types.float64, types.float64, _OUT_B, _OUT_B, _OUT_V)


@row_function
def _lane_row(valid, margin, pb, x, v, acc, t_stop, x_end, v_end, r, row_acc, dt, length):
    """One scenario of :func:`lane_kernel`: row ``pb`` of the pairs' ``valid``/``margin`` (``(., K-1)``), row ``r``
    of the vehicles' arrays (indexed in place, as :func:`_ego_row`). Returns ``(collided, violated, min_ratio)``."""
    ratio = INF
    hit, close = False, False
    for c in range(x.shape[1] - 1):
        if not valid[pb, c]:
            continue
        m = margin[pb, c]
        if not lane_near(SCALAR, True, x[r, c], v[r, c], x_end[r, c], v_end[r, c], x[r, c + 1], v[r, c + 1],
                         x_end[r, c + 1], v_end[r, c + 1], m, row_acc, dt):  # fmt: skip
            ratio = _min(ratio, lane_far_ratio(SCALAR, True, x[r, c + 1] - x[r, c], x_end[r, c + 1] - x_end[r, c], m))
            continue
        if t_stop[r, c] >= dt and t_stop[r, c + 1] >= dt:  # one quadratic over the period
            low = quadratic_extrema(SCALAR, x[r, c + 1] - x[r, c], v[r, c + 1] - v[r, c], acc[r, c + 1] - acc[r, c],
                                    dt)[0]  # fmt: skip
        else:  # someone stops inside the period
            low = stop_pair_extrema(SCALAR, x[r, c], v[r, c], acc[r, c], t_stop[r, c], x[r, c + 1], v[r, c + 1],
                                    acc[r, c + 1], t_stop[r, c + 1], dt)[0]  # fmt: skip
        pair_hit, pair_close, pair_ratio = lane_verdict(SCALAR, low, m, length)
        hit, close = hit or pair_hit, close or pair_close
        ratio = _min(ratio, pair_ratio)
    return hit, close, ratio


@row_function
def _switch_pair(x, v, f_acc, f_ts, f_xe, f_ve, c, sw, o_t, o_x, o_v, o_a, m, row_acc, dt, length, scratch):
    """:func:`~.checks.lane_checks`' pair of vehicle ``c`` (one segment: ``f_*[c]`` as ``constant_segment`` gives it,
    from ``x[c]``, ``v[c]``) behind vehicle ``c + 1``, whose acceleration switches inside the period (its knots in
    ``sw``, ``_fast_rows.Switched``, from ``_fast_world._switched``; its end state in ``f_xe``, ``f_ve``): near, the
    exact minimum of the gap over both motions (``gap_extrema``: the general path's, ``_general_pair``, over a lateral
    motion above the level all period, ``sw``'s ``lat_*``; ``c``'s knots into ``o_*``); far, the ratio at the period's
    ends. Returns ``(collided, violated, ratio)``."""
    a = c + 1
    if not lane_near(SCALAR, True, x[c], v[c], f_xe[c], f_ve[c], x[a], v[a], f_xe[a], f_ve[a], m, row_acc, dt):
        return False, False, lane_far_ratio(SCALAR, True, x[a] - x[c], f_xe[a] - f_xe[c], m)
    o_t[0], o_t[1], o_t[2] = 0.0, f_ts[c], dt
    o_x[0], o_x[1], o_x[2] = x[c], f_xe[c], f_xe[c]
    o_v[0], o_v[1], o_v[2] = v[c], f_ve[c], f_ve[c]
    o_a[0], o_a[1] = f_acc[c], 0.0
    sw.lat_t[1] = dt  # (a lateral motion above the level all period: the gap's extrema, unwindowed)
    low = _general_pair(o_t, o_x, o_v, o_a, sw.t, sw.x, sw.v, sw.a, sw.lat_t, sw.lat_x, sw.lat_v, sw.lat_a, 0.0,
                        scratch)[0]  # fmt: skip
    return lane_verdict(SCALAR, low, m, length)


@kernel(_LANE_SIGNATURE)
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
