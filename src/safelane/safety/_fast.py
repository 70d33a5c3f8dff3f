"""Optional compiled kernel of :func:`~.evasion.evasion_exists` (numba; extra ``fast``).

:func:`exists_kernel` is :func:`~.evasion.evasion_core`'s arithmetic — the lateral time of Eq. 5
(:func:`~.lateral.lateral_core`), the five switch-time candidates of Eqs. 6–8 and their exact leader gaps
(:func:`~.longitudinal.longitudinal_core`, :func:`~.longitudinal.leader_gap_min`, :func:`~.longitudinal.profile`),
the seven follower candidates of Eq. 9 clipped to ``[0, t_y_f]`` (:func:`~.longitudinal.ego_position`,
:func:`~.evasion.follower_offset`) and the same tolerance — fused into one loop over the batch, one element at a
time, so the few hundred element-wise temporaries of the NumPy path never touch memory.

**Same bits.** Every expression is written in the NumPy path's evaluation order (``0.5 * a * t * t`` is
``((0.5 * a) * t) * t`` in both), numba compiles without ``fastmath`` (so LLVM neither contracts ``a * b + c`` into
a fused multiply-add nor reassociates), and ``sqrt`` and ``/`` are correctly rounded in both. ``_max`` / ``_min``
propagate NaN as ``np.maximum`` / ``np.minimum`` do, and the guarded divisions take the same branches as
``_backend.ARRAY``. The gaps therefore come out bit-identical to the NumPy path's (``tests/test_fast_core.py``
compares them, not only the verdicts). What the loop skips changes no value:

* an element with nothing to evade (``t_y_f = 0``) evaluates its candidates only at 0, where every candidate clips
  to (the NumPy path does the same for a chunk where that holds everywhere);
* ``longitudinal_core`` keeps the largest switch-time candidate whose gap is feasible; the kernel tries them from
  the largest (``t_y_f``) down and stops at the first feasible one — the same candidate, hence the same gap;
* without ``gaps`` an element stops once its verdict is known: nothing to evade (True), no feasible profile even
  with full braking from 0 (False), or a follower candidate below the margin (False; the minimum only falls).

The NumPy path stays the reference and the fallback: this module is imported only by
:func:`~.evasion.evasion_exists` for large NumPy batches, and only when numba imports and ``SAFELANE_NO_NUMBA`` is
not ``1``. Compiled code is cached on disk (``cache=True``: ``__pycache__`` beside this file, or numba's
``NUMBA_CACHE_DIR``), so the compile (a few seconds) is paid once per machine and numba version.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types

from ._fast_base import (
    _B,
    _F,
    _INF,
    _braked,
    _max,
    _min,
    _nan_to_neg,
    _sqrt,
    _stop_dist,
    _stop_time,
    announce_compile,
)

# responsible.responsible_bound's dispatch finds its kernel here (fast_kernel() is this module): re-exported
from ._fast_responsible import responsible, responsible_kernel  # noqa: F401

announce_compile(__file__)

# One explicit signature (compiled at import, or loaded from the cache): read-only 1-D arrays of any layout, so
# contiguous inputs, broadcast scalars (stride 0) and read-only views all take the same machine code.
_SIGNATURE = types.void(
    *(_F,) * 9, _B, _F, _F, *(types.float64,) * 6, types.Array(types.bool_, 1, "C"), types.Array(types.float64, 2, "C")
)


@numba.njit(inline="always")
def _profile(u, v, v1, a1, a_a, a_d, l1_stop):  # longitudinal.profile -> (V, t2, match)
    V = v + a_a * u
    rel = V - _max(v1 - a1 * u, 0.0)
    m = a_d - a1
    if rel == 0.0:
        t_match = u + 0.0
    else:
        t_match = u + (rel / m if m != 0.0 else _INF)
    match = (rel >= 0.0) and (t_match <= l1_stop)
    t2 = t_match if match else u + V / a_d
    return V, t2, match


@numba.njit(error_model="numpy", nogil=True)
def _leader_gap_min(u, T, d0, p, v, p1, v1, a1, margin, a_a, a_d, l1_stop, l1_at_T):  # longitudinal.leader_gap_min
    V, t2, match = _profile(u, v, v1, a1, a_a, a_d, l1_stop)
    at_u = p + v * u + 0.5 * a_a * u * u
    t_b = _min(t2, T)
    tb = _max(_min(T, t2) - u, 0.0)
    braking_T = at_u + V * tb - 0.5 * a_d * tb * tb
    if match:
        l1_at_t2 = _braked(p1, v1, a1, t2, l1_stop)
        ego_at_T = braking_T + (_braked(p1, v1, a1, _max(T, t2), l1_stop) - l1_at_t2)
    else:
        ego_at_T = braking_T + 0.0
    gmin = _min(d0, (_braked(p1, v1, a1, u, l1_stop) - at_u) - margin)
    tb = _max(_min(t_b, t2) - u, 0.0)
    braking_tb = at_u + V * tb - 0.5 * a_d * tb * tb
    gmin = _min(gmin, (_braked(p1, v1, a1, t_b, l1_stop) - braking_tb) - margin)
    return _min(gmin, (l1_at_T - ego_at_T) - margin)


@numba.njit(inline="always")
def _ego_position(t, p, v, u, V, t2, match, p1, v1, a1, a_a, a_d, l1_stop):  # longitudinal.ego_position
    ta = _min(t, u)
    pos = p + v * ta + 0.5 * a_a * ta * ta
    tb = _max(_min(t, t2) - u, 0.0)
    pos = pos + V * tb - 0.5 * a_d * tb * tb
    if match:
        t_late = _max(t, t2)
        return pos + (_braked(p1, v1, a1, t_late, l1_stop) - _braked(p1, v1, a1, t2, l1_stop))
    return pos + 0.0


@numba.njit(error_model="numpy", nogil=True)
def _follow_gap(
    c, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, f_p, f_v, aggr, margin, a_a, a_d, l1_stop, f_stop
):
    ego = _ego_position(c, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, a_a, a_d, l1_stop)
    if aggr:  # evasion.follower_offset
        follower = f_p + f_v * c + 0.5 * a_a * c * c
    else:
        follower = _braked(f_p, f_v, a_d, c, f_stop)
    return ego - follower - margin


@numba.njit(inline="always")
def _lateral_time(py, vy, a_y, y_safe, lat_tol):
    """:func:`~.lateral.lateral_core`'s ``t_y_f`` (Eq. 5)."""
    e = py - y_safe
    sl = e + vy * abs(vy) / (2.0 * a_y)
    if (e <= lat_tol) and ((vy <= 0.0) or (sl <= lat_tol)):  # nothing to evade
        return 0.0
    if sl > 0.0:
        return (vy + 2.0 * _sqrt(a_y * e + 0.5 * vy * vy)) / a_y
    return (-vy - _sqrt(vy * vy - 2.0 * a_y * e)) / a_y


@numba.njit(error_model="numpy", nogil=True)
def _leader_search(T, gap0, d0, p, v, p1, v1, a1, margin, a_a, a_d, s, s_a, l1_stop, l1_at_T, tol):
    """:func:`~.longitudinal.longitudinal_core`'s choice of the switch time: ``(u, its leader gap)``; ``gap0`` is the
    gap of ``u = 0``, kept when no candidate is feasible."""
    best = 0.0 * T
    best_gap = gap0
    if T != 0.0:  # with nothing to evade every candidate clips to 0, the first
        # longitudinal_core keeps the largest candidate whose gap is feasible (a later one on a tie, which has
        # the same gap: it is the same arithmetic on the same number). Trying them from the largest down and
        # stopping at the first feasible one selects the same candidate with the same gap.
        g = _leader_gap_min(T, T, d0, p, v, p1, v1, a1, margin, a_a, a_d, l1_stop, l1_at_T)
        if g >= -tol:
            return T, g
        big_r = l1_at_T - margin - p - v * T
        u_a = T - _sqrt(T * T - (a_d * T * T + 2.0 * big_r) / s)
        p1_stop = p1 + _stop_dist(v1, a1)
        u_b = -v / a_a + _sqrt((v / a_a) * (v / a_a) - (v * v + 2.0 * a_d * (p + margin - p1_stop)) / s_a)
        w = v - v1
        k = a_a + a1
        u_c = (-w + _sqrt(w * w - k * (w * w - 2.0 * (a_d - a1) * d0) / s)) / k
        # clipped to [0, T]; a NaN (never selected: `cand >= best` is false) becomes -1, never tried
        c1 = _nan_to_neg(_min(_max(u_a, 0.0), T))
        c2 = _nan_to_neg(_min(_max(u_b, 0.0), T))
        c3 = _nan_to_neg(_min(_max(u_c, 0.0), T))
        if c1 < c2:
            c1, c2 = c2, c1
        if c2 < c3:
            c2, c3 = c3, c2
        if c1 < c2:
            c1, c2 = c2, c1
        for j in range(3):
            cand = c1 if j == 0 else (c2 if j == 1 else c3)
            if cand < 0.0 or cand == T:  # never tried / the same number as T, which failed
                continue
            g = _leader_gap_min(cand, T, d0, p, v, p1, v1, a1, margin, a_a, a_d, l1_stop, l1_at_T)
            if g >= -tol:
                return cand, g
    return best, best_gap


@numba.njit(error_model="numpy", nogil=True)
def _follow_min(T, p, v, u, V, t2, match, p1, v1, a1, fp, fv, aggr, fmargin, a_a, a_d, s, l1_stop, tol, early):
    """The follower gap of Eq. 9: its minimum over the seven candidates clipped to ``[0, T]``; ``early`` stops once
    it is below ``-tol`` (the minimum only falls: the verdict is known). ``s`` is ``a_a + a_d``."""
    f_stop = _stop_time(fv, a_d)
    fgap = _follow_gap(0.0 * T, p, v, u, V, t2, match, p1, v1, a1, fp, fv, aggr, fmargin, a_a, a_d, l1_stop, f_stop)
    if T != 0.0:
        m1 = a_d - a1
        for j in range(6):
            if j == 0:
                cand = u
            elif j == 1:
                cand = t2
            elif j == 2:
                cand = f_stop
            elif j == 3:
                cand = (fv - v) / s
            elif j == 4:
                cand = (fv - v1) / m1 if m1 != 0.0 else 0.0
            else:
                cand = T
            cand = _min(_max(cand, 0.0), T)
            fgap = _min(
                fgap,
                _follow_gap(cand, p, v, u, V, t2, match, p1, v1, a1, fp, fv, aggr, fmargin, a_a, a_d, l1_stop, f_stop),
            )
            if early and not fgap >= -tol:  # the minimum can only fall further: False
                break
    return fgap


@numba.njit(_SIGNATURE, cache=True, nogil=True)
def exists_kernel(
    ego_px,
    ego_py,
    ego_vx,
    ego_vy,
    l1_p,
    l1_v,
    l1_decel,
    f_p,
    f_v,
    aggressive,
    lead_margin,
    follow_margin,
    a_a,
    a_d,
    a_y,
    y_safe,
    lat_tol,
    tol,
    out,
    gaps,
):
    """Write :func:`~.evasion.evasion_core`'s ``exists`` for each element into ``out`` (bool, length ``n``).

    Every input is a 1-D array of length ``n`` (stride 0 for a broadcast scalar). ``gaps`` is ``(2, n)`` to also
    receive ``lead_gap`` and ``follow_gap`` (every element then evaluated in full, for the tests), or ``(2, 0)``.
    """
    n = out.shape[0]
    want_gaps = gaps.shape[1] == n and n > 0
    s = a_a + a_d
    s_a = s * a_a
    for i in range(n):
        T = _lateral_time(ego_py[i], ego_vy[i], a_y, y_safe, lat_tol)
        if T <= 0.0 and not want_gaps:
            out[i] = True
            continue
        # longitudinal_core
        p = ego_px[i]
        v = ego_vx[i]
        p1 = l1_p[i]
        v1 = l1_v[i]
        a1 = l1_decel[i]
        margin = lead_margin[i]
        d0 = p1 - p - margin
        l1_stop = _stop_time(v1, a1)
        l1_at_T = _braked(p1, v1, a1, T, l1_stop)
        best_gap = _leader_gap_min(0.0 * T, T, d0, p, v, p1, v1, a1, margin, a_a, a_d, l1_stop, l1_at_T)
        feasible = best_gap >= -tol
        if not feasible and not want_gaps:
            out[i] = False
            continue
        u, best_gap = _leader_search(T, best_gap, d0, p, v, p1, v1, a1, margin, a_a, a_d, s, s_a, l1_stop, l1_at_T, tol)
        V, t2, match = _profile(u, v, v1, a1, a_a, a_d, l1_stop)
        fgap = _follow_min(
            T,
            p,
            v,
            u,
            V,
            t2,
            match,
            p1,
            v1,
            a1,
            f_p[i],
            f_v[i],
            aggressive[i],
            follow_margin[i],
            a_a,
            a_d,
            s,
            l1_stop,
            tol,
            not want_gaps,
        )
        out[i] = (T <= 0.0) or (feasible and fgap >= -tol)
        if want_gaps:
            gaps[0, i] = best_gap
            gaps[1, i] = fgap


def run(args, shape, params, tol: float, lat_tol: float, want_gaps: bool = False):
    """Evaluate :func:`exists_kernel` on ``evasion_core``'s argument tuple (arrays broadcastable to ``shape``).

    Returns ``exists`` (bool, ``shape``) and, with ``want_gaps``, ``(lead_gap, follow_gap)`` as a ``(2, n)`` array
    (``n`` the number of elements). Scalars are passed with stride 0 and full contiguous arrays as they are."""
    n = math.prod(shape)
    flat = []
    for j, a in enumerate(args):
        a = np.asarray(a, dtype=np.bool_ if j == 9 else np.float64)
        flat.append(np.broadcast_to(a, (n,)) if a.size == 1 else np.broadcast_to(a, shape).reshape(-1))
    out = np.empty(n, dtype=np.bool_)
    gaps = np.empty((2, n if want_gaps else 0))
    exists_kernel(*flat, params.a_x_a, params.a_x_d, params.a_y_m, params.y_safe, lat_tol, tol, out, gaps)
    out = out.reshape(shape)
    return (out, gaps) if want_gaps else out
