"""Optional compiled kernel of the ego checks' general path (:func:`~.kinematics.windowed_gap_extrema` over
:func:`~.kinematics.crossing_knots`; numba, extra ``fast``).

:func:`general_kernel` is that path per pair of motions — the ego on its evasion plan (several segments), or stopping
while it crosses a lateral level — with the knots merged and sorted as NumPy's: the pairs that
:func:`._fast_checks.ego_kernel` leaves, and the compiled loop's (``_fast_loop``, through :func:`_general_pair`). The
same bits as the NumPy path (``tests/test_fast_checks.py``).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types

from ..safety._fast_base import (
    _max,
    _min,
    announce_compile,
)

announce_compile(__file__)

_INF = np.inf
_OUT_V = types.Array(types.float64, 1, "C")
_K = types.Array(types.float64, 2, "A", readonly=True)
_GENERAL_SIGNATURE = types.void(*(_K,) * 12, types.float64, _OUT_V, _OUT_V)


@numba.njit(inline="always")
def _at(t, x, v, acc, tq):  # kinematics.Motion.at for one motion (knots t, x, v; segment accelerations) at tq: (x, v)
    seg = 0
    for j in range(1, t.shape[0] - 1):
        if t[j] <= tq:
            seg += 1
    tau = tq - t[seg]
    a = acc[seg]
    return x[seg] + v[seg] * tau + 0.5 * a * tau * tau, v[seg] + a * tau


@numba.njit(error_model="numpy", nogil=True)
def _general_pair(bt, bx, bv, bacc, at, ax, av, aacc, lt, lx, lv, lacc, level, knots):
    """One pair of :func:`general_kernel` (1-D motions; ``knots`` scratch of the merged size): ``(min, max)``."""
    nl = lt.shape[0]
    size = bt.shape[0] + at.shape[0] + nl + 2 * (nl - 1)
    k = 0
    for j in range(bt.shape[0]):
        knots[k] = bt[j]
        k += 1
    for j in range(at.shape[0]):
        knots[k] = at[j]
        k += 1
    for j in range(nl):
        knots[k] = lt[j]
        k += 1
    for root in range(2):  # crossing_knots: each segment's roots of x(t) = level inside it (else its start)
        for j in range(nl - 1):
            t0, span = lt[j], lt[j + 1] - lt[j]
            y0, v0, a = lx[j] - level, lv[j], lacc[j]
            disc = v0 * v0 - 2.0 * a * y0
            rt = np.sqrt(_max(disc, 0.0))
            if a != 0.0 and disc >= 0.0:
                r = ((-v0 - rt) if root == 0 else (-v0 + rt)) / a
            elif root == 0 and a == 0.0 and v0 != 0.0:
                r = -y0 / v0
            else:
                r = -1.0
            knots[k] = t0 + r if (r > 0.0 and r < span) else t0
            k += 1
    merged = knots[:size]
    merged.sort()
    low, high = _INF, -_INF
    xa, va = _at(at, ax, av, aacc, merged[0])
    xb, vb = _at(bt, bx, bv, bacc, merged[0])
    d0, dv0 = xa - xb, va - vb
    for j in range(size - 1):
        xa, va = _at(at, ax, av, aacc, merged[j + 1])
        xb, vb = _at(bt, bx, bv, bacc, merged[j + 1])
        d1, dv1 = xa - xb, va - vb
        mid = 0.5 * (merged[j] + merged[j + 1])
        if _at(lt, lx, lv, lacc, mid)[0] > level:
            span = merged[j + 1] - merged[j]
            ra = (dv1 - dv0) / span if span > 0.0 else 0.0
            tau = -dv0 / ra if ra != 0.0 else -1.0
            inside = tau > 0.0 and tau < span
            vertex = d0 + dv0 * tau + 0.5 * ra * tau * tau
            low = _min(low, _min(_min(d0, d1), vertex if (inside and ra > 0.0) else _INF))
            high = _max(high, _max(_max(d0, d1), vertex if (inside and ra < 0.0) else -_INF))
        d0, dv0 = d1, dv1
    return low, high


@numba.njit(_GENERAL_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def general_kernel(bt, bx, bv, bacc, at, ax, av, aacc, lt, lx, lv, lacc, level, lo, hi):
    """:func:`~.kinematics.windowed_gap_extrema` of ``ahead − behind`` (``b*``, ``a*``: the motions' knots ``t``,
    ``x``, ``v`` and segment accelerations, one row per pair) over the instants where the lateral motion (``l*``)
    is above ``level``, its window from :func:`~.kinematics.crossing_knots` — the NumPy functions' arithmetic per
    pair, knots merged and sorted as theirs."""
    nl = lt.shape[1]
    knots = np.empty(bt.shape[1] + at.shape[1] + nl + 2 * (nl - 1))
    for p in range(lo.shape[0]):
        lo[p], hi[p] = _general_pair(bt[p], bx[p], bv[p], bacc[p], at[p], ax[p], av[p], aacc[p], lt[p], lx[p], lv[p],
                                     lacc[p], level, knots)  # fmt: skip


def _general(ego_lon, ahead, ego_lat, level: float):
    """:func:`general_kernel` on three :class:`~.kinematics.Motion` of one row per pair: ``(min, max)``."""
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    lo, hi = np.empty(len(ego_lon.t)), np.empty(len(ego_lon.t))
    motions = [f(getattr(m, name)) for m in (ego_lon, ahead, ego_lat) for name in ("t", "x", "v", "acc")]
    general_kernel(*motions, level, lo, hi)
    return lo, hi


