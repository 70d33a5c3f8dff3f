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

_INF = math.inf

# One explicit signature (compiled at import, or loaded from the cache): read-only 1-D arrays of any layout, so
# contiguous inputs, broadcast scalars (stride 0) and read-only views all take the same machine code.
_F = types.Array(types.float64, 1, "A", readonly=True)
_B = types.Array(types.bool_, 1, "A", readonly=True)
_SIGNATURE = types.void(
    *(_F,) * 9, _B, _F, _F, *(types.float64,) * 6, types.Array(types.bool_, 1, "C"), types.Array(types.float64, 2, "C")
)


@numba.njit(inline="always")
def _max(a, b):
    return a if (a >= b or a != a) else b  # NaN propagates (np.maximum)


@numba.njit(inline="always")
def _min(a, b):
    return a if (a <= b or a != a) else b  # NaN propagates (np.minimum)


@numba.njit(inline="always")
def _sqrt(x):
    return math.sqrt(_max(x, 0.0))  # _Array.sqrt


@numba.njit(inline="always")
def _nan_to_neg(x):
    return x if x == x else -1.0


@numba.njit(inline="always")
def _stop_time(v, a):
    if a > 0.0:
        return v / a
    return _INF if v > 0.0 else 0.0


@numba.njit(inline="always")
def _stop_dist(v, a):
    if a > 0.0:
        return v * v / (2.0 * a)
    return _INF if v > 0.0 else 0.0


@numba.njit(inline="always")
def _braked(p, v, decel, t, t_stop):  # chain.braked_position
    tt = _min(t, t_stop)
    return p + v * tt - 0.5 * decel * tt * tt


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


@numba.njit(inline="always")
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


@numba.njit(inline="always")
def _follow_gap(
    c, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, f_p, f_v, aggr, margin, a_a, a_d, l1_stop, f_stop
):
    ego = _ego_position(c, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, a_a, a_d, l1_stop)
    if aggr:  # evasion.follower_offset
        follower = f_p + f_v * c + 0.5 * a_a * c * c
    else:
        follower = _braked(f_p, f_v, a_d, c, f_stop)
    return ego - follower - margin


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
    c_ev = a_a + a_d
    for i in range(n):
        # lateral_core: t_y_f
        py = ego_py[i]
        vy = ego_vy[i]
        e = py - y_safe
        sl = e + vy * abs(vy) / (2.0 * a_y)
        nothing = (e <= lat_tol) and ((vy <= 0.0) or (sl <= lat_tol))
        if nothing:
            T = 0.0
        elif sl > 0.0:
            r = _sqrt(a_y * e + 0.5 * vy * vy)
            T = (vy + 2.0 * r) / a_y
        else:
            T = (-vy - _sqrt(vy * vy - 2.0 * a_y * e)) / a_y
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
        best = 0.0 * T
        best_gap = _leader_gap_min(best, T, d0, p, v, p1, v1, a1, margin, a_a, a_d, l1_stop, l1_at_T)
        feasible = best_gap >= -tol
        if not feasible and not want_gaps:
            out[i] = False
            continue
        if T != 0.0:  # with nothing to evade every candidate clips to 0, the first
            # longitudinal_core keeps the largest candidate whose gap is feasible (a later one on a tie, which has
            # the same gap: it is the same arithmetic on the same number). Trying them from the largest down and
            # stopping at the first feasible one selects the same candidate with the same gap.
            g = _leader_gap_min(T, T, d0, p, v, p1, v1, a1, margin, a_a, a_d, l1_stop, l1_at_T)
            if g >= -tol:
                best = T
                best_gap = g
            else:
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
                        best = cand
                        best_gap = g
                        break
        u = best
        V, t2, match = _profile(u, v, v1, a1, a_a, a_d, l1_stop)
        # the follower (Eq. 9) at the seven candidates
        fp = f_p[i]
        fv = f_v[i]
        aggr = aggressive[i]
        fmargin = follow_margin[i]
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
                    cand = (fv - v) / c_ev
                elif j == 4:
                    cand = (fv - v1) / m1 if m1 != 0.0 else 0.0
                else:
                    cand = T
                cand = _min(_max(cand, 0.0), T)
                fgap = _min(
                    fgap,
                    _follow_gap(
                        cand, p, v, u, V, t2, match, p1, v1, a1, fp, fv, aggr, fmargin, a_a, a_d, l1_stop, f_stop
                    ),
                )
                if not want_gaps and not fgap >= -tol:  # the minimum can only fall further: False
                    break
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


# ---------------------------------------------------------------------------------------------------------------
# Responsible following (issue 13): responsible.responsible_bound fused, element by element
# ---------------------------------------------------------------------------------------------------------------

_RESPONSIBLE_SIGNATURE = types.void(*(_F,) * 5, types.float64, types.Array(types.float64, 1, "C"))


@numba.njit(_RESPONSIBLE_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def responsible_kernel(slack, v_f, v_l, lead_decel, brake, dt, out):
    """:func:`~.responsible.responsible_bound` (the smallest of :func:`~.responsible.responsible_bounds`) per element,
    each expression in the NumPy path's evaluation order, divisions as NumPy's (``error_model="numpy"``: ``x / 0``
    is ``±inf`` or NaN, never an exception), and the minimum taken in the same order with NaN propagating — the
    same bits (``tests/test_fast_core.py``)."""
    inf = _INF
    for i in range(out.shape[0]):
        s = slack[i] + 0.0  # −0.0 → +0.0, as the NumPy path
        vf, vl, d, b = v_f[i], v_l[i], lead_decel[i], brake[i]
        # _motion.advance(s, v_l, −d, dt): the leader's gap position and speed at dt, stopping at rest
        a = -d
        ts = _min(vl / -a, dt) if a < 0.0 else dt
        xl_end = s + vl * ts + 0.5 * a * ts * ts
        u1 = 0.0 if ts < dt else _max(vl + a * dt, 0.0)
        g = xl_end - vf * dt
        end = 2.0 * g / (dt * dt)
        if not vf + end * dt >= 0.0:
            end = -vf * vf / (2.0 * xl_end)
        dv = vf - vl
        tau = 2.0 * s / dv
        in_period = dv > 0.0 and s >= 0.0 and tau < dt and vl - d * tau > 0.0
        c = b - d
        r0 = vf - u1
        disc = c * c * dt * dt + 4.0 * c * (2.0 * g + dt * r0)
        q = 0.5 * (-c * dt + (math.sqrt(disc) if disc >= 0.0 else math.nan))
        after_period = c > 0.0 and disc >= 0.0 and q > 0.0 and u1 > 0.0 and q * d <= c * u1
        # final_stop_accel(s, v_f, v_l, d, brake)
        if d > 0.0:
            lead_stop = vl * vl / (2.0 * d)
        else:
            lead_stop = inf if vl > 0.0 else 0.0
        y = s + lead_stop
        w = -0.5 * b * dt + _sqrt(0.25 * b * b * dt * dt + b * (2.0 * y - vf * dt))
        if w >= 0.0:
            a_final = (w - vf) / dt
        else:
            a_final = -vf * vf / (2.0 * y) if y > 0.0 else -inf
        if y == inf:
            final = inf
        elif y <= 0.0:
            final = 0.0 if (y == 0.0 and vf == 0.0) else -inf
        else:
            final = a_final
        # the five bounds, in responsible_bounds' order: inside, final, end, in_period, after_period
        r = inf if s >= 0.0 else -inf
        r = _min(r, final)
        r = _min(r, end if xl_end > 0.0 else (-inf if xl_end < 0.0 else 0.0))
        r = _min(r, -d - dv * dv / (2.0 * s) if in_period else inf)
        r = _min(r, (q - r0) / dt if after_period else inf)
        out[i] = r


def _readonly(a: np.ndarray) -> np.ndarray:
    view = a.view()
    view.flags.writeable = False
    return view


def responsible(slack, v_f, v_l, lead_decel, brake, dt: float) -> np.ndarray:
    """:func:`responsible_kernel` on arrays broadcast to one shape; returns that shape."""
    arrays = [np.asarray(x, dtype=np.float64) for x in (slack, v_f, v_l, lead_decel, brake)]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    n = math.prod(shape)
    # Scalars with stride 0, arrays of the full shape as they are (read-only views: the signature takes any layout).
    flat = [np.broadcast_to(a.reshape(-1), (n,)) if a.size == 1 else np.broadcast_to(a, shape).reshape(-1)
            for a in arrays]  # fmt: skip
    # Read-only views set explicitly: a view of an np.broadcast_arrays output (a column of one) would otherwise make
    # numba's typing read its deprecated "writeable with a warning" flag and emit NumPy's FutureWarning.
    flat = [_readonly(f) for f in flat]
    out = np.empty(n)
    responsible_kernel(*flat, float(dt), out)
    return out.reshape(shape)
