"""Optional compiled kernel of the ego checks' general path (:func:`~.kinematics.windowed_gap_extrema` over
:func:`~.kinematics.crossing_knots`; numba, extra ``fast``): loops, indexing and the knot merging a row needs.

:func:`general_kernel` is that path per pair of motions — the ego on its evasion plan (several segments), or stopping
while it crosses a lateral level: the pairs that :func:`._fast_checks.ego_kernel` leaves, and the compiled loop's
(``_fast_loop``, through :func:`_general_pair`). The arithmetic is kinematics' own, compiled as it is
(:func:`~.kinematics.segment_crossings` per lateral segment, :func:`~.kinematics.state_at` at each knot,
:func:`~.kinematics.windowed_piece` per interval); the knots are merged into scratch and sorted as NumPy's, so the
bits are the NumPy path's (``tests/test_fast_checks.py``).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types

from ..safety import _compile
from ..safety._backend import INF, SCALAR
from ..safety._fast_base import _max, _min, announce_compiles, kernel, sort_short
from .kinematics import segment_crossings, state_at, windowed_piece

_compile.register_rows()
announce_compiles()

_OUT_V = types.Array(types.float64, 1, "C")
_K = types.Array(types.float64, 2, "A", readonly=True)
_GENERAL_SIGNATURE = types.void(*(_K,) * 12, types.float64, _OUT_V, _OUT_V)


@numba.njit(inline="always")
def _at(t, x, v, acc, tq):  # kinematics.Motion.at for one motion (knots t, x, v; segment accelerations) at tq: (x, v)
    seg = 0
    for j in range(1, t.shape[0] - 1):
        if t[j] <= tq:
            seg += 1
    return state_at(SCALAR, x[seg], v[seg], acc[seg], tq - t[seg])


@numba.njit(error_model="numpy", nogil=True)
def _general_pair(bt, bx, bv, bacc, at, ax, av, aacc, lt, lx, lv, lacc, level, knots):
    """One pair of :func:`general_kernel` (1-D motions; ``knots`` scratch of the merged size): ``(min, max)``."""
    nb, na, nl = bt.shape[0], at.shape[0], lt.shape[0]
    for j in range(nb):
        knots[j] = bt[j]
    for j in range(na):
        knots[nb + j] = at[j]
    for j in range(nl):
        knots[nb + na + j] = lt[j]
    first, second = nb + na + nl, nb + na + nl + nl - 1  # crossing_knots' extra knots: each segment's two roots
    for j in range(nl - 1):
        knots[first + j], knots[second + j] = segment_crossings(SCALAR, lt[j], lt[j + 1] - lt[j], lx[j], lv[j],
                                                                lacc[j], level)  # fmt: skip
    size = second + nl - 1
    merged = knots[:size]
    sort_short(merged)  # (not merged.sort(): the closed loop runs this without reference counting)
    low, high = INF, -INF
    xa, va = _at(at, ax, av, aacc, merged[0])
    xb, vb = _at(bt, bx, bv, bacc, merged[0])
    d0, dv0 = xa - xb, va - vb
    for j in range(size - 1):
        xa, va = _at(at, ax, av, aacc, merged[j + 1])
        xb, vb = _at(bt, bx, bv, bacc, merged[j + 1])
        d1, dv1 = xa - xb, va - vb
        y_mid = _at(lt, lx, lv, lacc, 0.5 * (merged[j] + merged[j + 1]))[0]
        lo, hi = windowed_piece(SCALAR, d0, dv0, d1, dv1, merged[j + 1] - merged[j], y_mid, level)
        low, high = _min(low, lo), _max(high, hi)
        d0, dv0 = d1, dv1
    return low, high


@kernel(_GENERAL_SIGNATURE)
def general_kernel(bt, bx, bv, bacc, at, ax, av, aacc, lt, lx, lv, lacc, level, lo, hi):
    """:func:`~.kinematics.windowed_gap_extrema` of ``ahead − behind`` (``b*``, ``a*``: the motions' knots ``t``,
    ``x``, ``v`` and segment accelerations, one row per pair) over the instants where the lateral motion (``l*``)
    is above ``level``, its window from :func:`~.kinematics.crossing_knots`, per pair."""
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
