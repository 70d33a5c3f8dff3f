"""Compiled responsible following (numba; extra ``fast``): :func:`~.responsible.responsible_bound` and the pieces of
:func:`~.responsible.responsible_ok` as scalar functions, and :func:`responsible_kernel`, the bound over a batch.

Each scalar function is its NumPy original per element, every expression in the same evaluation order, divisions
with NumPy's semantics (callers compile with ``error_model="numpy"``: ``x / 0`` is ``±inf`` or NaN, never an
exception; the helpers are inlined, so the caller's model applies), minima and maxima propagating NaN as
``np.minimum``/``np.maximum`` — the same bits (``tests/test_fast_responsible.py``; the simulator's leaders,
``tests/test_fast_traffic.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types

from ._fast_base import (
    _F,
    _INF,
    _max,
    _min,
    _sqrt,
    announce_compile,
    readonly,
)

announce_compile(__file__)

_RESPONSIBLE_SIGNATURE = types.void(*(_F,) * 5, types.float64, types.Array(types.float64, 1, "C"))


@numba.njit(error_model="numpy", nogil=True)
def _responsible_bound(slack, vf, vl, d, b, dt):
    """:func:`~.responsible.responsible_bound` (the smallest of :func:`~.responsible.responsible_bounds`)."""
    inf = _INF
    s = slack + 0.0  # −0.0 → +0.0, as the NumPy path
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
    return _min(r, (q - r0) / dt if after_period else inf)


@numba.njit(inline="always")
def _stop_within(v, a, horizon):  # _motion.stop_time
    return _min(v / -a, horizon) if a < 0.0 else horizon


@numba.njit(inline="always")
def _advance(x, v, a, dt):  # _motion.advance -> (x', v')
    ts = _stop_within(v, a, dt)
    return x + v * ts + 0.5 * a * ts * ts, (0.0 if ts < dt else _max(v + a * dt, 0.0))


@numba.njit(error_model="numpy", nogil=True)
def _pair_min_gap(slack, v_f, a_f, v_l, a_l, dt):  # responsible.pair_min_gap
    ts_f = _stop_within(v_f, a_f, dt)
    ts_l = _stop_within(v_l, a_l, dt)
    dv = v_l - v_f
    da = a_f - a_l
    tau = dv / da if da != 0.0 else 0.0
    lowest = 0.0
    for j in range(4):  # the candidate instants: both stops, equal speeds (clipped), the period's end
        t = ts_f if j == 0 else (ts_l if j == 1 else (_min(_max(tau, 0.0), dt) if j == 2 else dt))
        m_f = _min(t, ts_f)
        m_l = _min(t, ts_l)
        xf = v_f * m_f + 0.5 * a_f * m_f * m_f
        xl = slack + v_l * m_l + 0.5 * a_l * m_l * m_l
        lowest = (xl - xf) if j == 0 else _min(lowest, xl - xf)  # NaN propagates, as .min(0)
    return _min(slack, lowest)


@numba.njit(error_model="numpy", nogil=True)
def _min_follow_decel(slack, v_f, v_l, a_l, half, tol):  # chain._min_follow_decel_array
    edge = _max(slack + half, 0.0) if slack >= -tol else slack
    s = slack if slack > half else edge
    if a_l > 0.0:
        lead_stop2 = v_l * v_l / a_l
    else:
        lead_stop2 = _INF if v_l > 0.0 else 0.0
    two_slack = 2.0 * s
    den = two_slack + lead_stop2
    z_b = v_f * v_f / den if den > 0.0 else 0.0
    dv = v_f - v_l
    z_a = a_l + dv * dv / two_slack
    interior = (dv > 0.0) and (two_slack * a_l <= v_l * dv)
    if s >= 0.0:
        return z_a if interior else z_b
    return _INF


@numba.njit(error_model="numpy", nogil=True)
def _responsible_ok(a, slack, v_f, v_l, lead_decel, brake, dt, tol, half, feas_tol):  # responsible.responsible_ok
    in_period = _pair_min_gap(slack, v_f, a, v_l, -lead_decel, dt) >= -tol
    xf, vf = _advance(0.0, v_f, a, dt)
    xl, vl = _advance(slack, v_l, -lead_decel, dt)
    z = _min_follow_decel(xl - xf, vf, vl, lead_decel, half, feas_tol)
    return in_period and z <= brake


@numba.njit(_RESPONSIBLE_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def responsible_kernel(slack, v_f, v_l, lead_decel, brake, dt, out):
    """:func:`~.responsible.responsible_bound` per element (:func:`_responsible_bound`) — the same bits
    (``tests/test_fast_responsible.py``)."""
    for i in range(out.shape[0]):
        out[i] = _responsible_bound(slack[i], v_f[i], v_l[i], lead_decel[i], brake[i], dt)


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
    flat = [readonly(f) for f in flat]
    out = np.empty(n)
    responsible_kernel(*flat, float(dt), out)
    return out.reshape(shape)
