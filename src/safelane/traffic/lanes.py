"""Who is where, lane by lane, for a batch of lane changes: the neighbours of every changer in its target and own
lanes (:func:`neighbours`, used by :meth:`.equipped.LaneChanges.situation`).

One source, compiled: :func:`neighbour_rows` is plain loops and indexing. Where numba imports and
``SAFELANE_NO_NUMBA`` is not ``1`` it runs compiled (:mod:`._fast_lanes`, the same function given to ``numba.njit``);
otherwise the same function runs as Python (a loop over the vehicles and the changers: slow at thousands of
vehicles, the same answers). The rules, also written changer by changer and lane by lane in
``tests/test_traffic_situation.py`` as the reference they are checked against:

* A vehicle belongs to every lane its body overlaps (one for a vehicle inside its lane, two for one across a lane
  boundary; none on the ramp). Within a lane, vehicles are ordered by position along the road, ties in fleet order.
* F is the nearest vehicle strictly behind the changer in the target lane, at the highest speed of the vehicles from
  it back to the nearest one that *stays* in that lane (a vehicle that is not changing lanes, or a changer settled
  into that lane; docs/traffic.md).
* The chain ``L1…L(M)`` are the nearest ``M`` strictly ahead in the target lane (padded ``far`` apart beyond the last,
  at the changer's speed), ``n_connected`` the equipped ones at its head (at most ``M − 1``).
* ``L0`` is the nearest strictly ahead in the own lane (``+inf`` where none); in the acceleration lane its end, a
  standing obstacle, where that is nearer.
"""

from __future__ import annotations

import numpy as np

from ..safety.evasion import fast_kernel
from . import demand as dem


def neighbour_rows(lane, y, x, v, equipped, lane_kept, centres, half, rows, target, g0, ex, evx, far, accel_lane,
                   accel_end, members, count, rank, fx, fv, fcon, lx, lv, chain_ids, n_conn, ox, ov):  # fmt: skip
    """The neighbours of each changer ``r`` (fleet index ``rows[r]``, lanes ``target[r]`` and ``g0[r]``, position
    ``ex[r]`` = ``x[rows[r]]``, speed ``evx[r]``), written into ``fx … ov``. Fleet arrays ``(V,)``: ``lane`` (``-1``
    on the ramp), road ``y``, ``x``, ``v``, ``equipped``, ``lane_kept`` (the lane each changer stays in, ``-1`` none
    yet; ``-2`` for a vehicle that is not changing lanes); ``centres``: each lane's centre ``y``; a body overlaps lane
    ``g`` when its centre is within ``half`` of ``centres[g]``. Work arrays: ``members`` ``(lanes, V)``, ``count``
    ``(lanes,)``, ``rank`` ``(V,)``."""
    n_v, n_lanes, m = len(x), len(centres), lx.shape[1]
    order = np.argsort(x, kind="mergesort")  # stable: ties in fleet order
    for g in range(n_lanes):
        count[g] = 0
    for k in range(n_v):
        i = order[k]
        rank[i] = 0 if k == 0 else rank[order[k - 1]] + (1 if x[i] != x[order[k - 1]] else 0)
        if lane[i] >= 0:
            for g in range(n_lanes):
                if abs(y[i] - centres[g]) < half:
                    members[g, count[g]] = i
                    count[g] += 1
    for r in range(len(rows)):
        q = rank[rows[r]]
        t = target[r]
        lo = _first(members, count, rank, t, q, False)
        hi = _first(members, count, rank, t, q, True)
        if lo > 0:
            near = members[t, lo - 1]
            fx[r], fcon[r] = x[near], equipped[near]
            best = v[near]
            k = lo - 1
            while lane_kept[members[t, k]] != -2 and lane_kept[members[t, k]] != t and k > 0:
                k -= 1
                if v[members[t, k]] > best:
                    best = v[members[t, k]]
            fv[r] = best
        else:
            fx[r], fv[r], fcon[r] = ex[r] - far, 0.0, False
        n_conn[r] = 0
        leading = True
        for j in range(m):
            if hi + j < count[t]:
                i = members[t, hi + j]
                lx[r, j], lv[r, j], chain_ids[r, j] = x[i], v[i], i
                leading = leading and equipped[i]
            else:
                lx[r, j], lv[r, j], chain_ids[r, j] = ex[r] + far * (1.0 + j), evx[r], -1
                leading = False
            if leading and j < m - 1:
                n_conn[r] += 1
        own = _first(members, count, rank, g0[r], q, True)
        if own < count[g0[r]]:
            ox[r], ov[r] = x[members[g0[r], own]], v[members[g0[r], own]]
        else:
            ox[r], ov[r] = np.inf, 0.0
        if g0[r] == accel_lane and not ox[r] < accel_end:
            ox[r], ov[r] = accel_end, 0.0


def _first(members, count, rank, g, q, beyond):
    """The first position in lane ``g`` whose vehicle's rank is ``> q`` (``beyond``) or ``>= q`` (a bisection)."""
    lo, hi = 0, count[g]
    while lo < hi:
        mid = (lo + hi) // 2
        r = rank[members[g, mid]]
        if r < q or (beyond and r == q):
            lo = mid + 1
        else:
            hi = mid
    return lo


def neighbours(fleet, x, lane_kept, rows, target, g0, ex, evx, m: int, far: float, half: float, accel_end: float):
    """:func:`neighbour_rows` for a batch (compiled where the kernels are): ``(fx, fv, fcon, lx, lv, chain_ids,
    n_conn, ox, ov)``, ``(B,)`` and ``(B, m)`` arrays; ``x``: the fleet's positions with the changers at theirs."""
    b, n_v = len(rows), len(x)
    out = (np.empty(b), np.empty(b), np.empty(b, np.bool_), np.empty((b, m)), np.empty((b, m)),
           np.empty((b, m), np.int64), np.empty(b, np.int64), np.empty(b), np.empty(b))  # fmt: skip
    centres = dem.lane_y(np.arange(dem.N_LANES))
    kernel = _kernel()
    run = neighbour_rows if kernel is None else kernel.neighbour_kernel
    run(np.asarray(fleet.lane, np.int64), np.asarray(fleet.y, float), np.asarray(x, float), np.asarray(fleet.v, float),
        np.asarray(fleet.equipped, np.bool_), np.asarray(lane_kept, np.int64), centres, float(half),
        np.asarray(rows, np.int64), np.asarray(target, np.int64), np.asarray(g0, np.int64), np.asarray(ex, float),
        np.asarray(evx, float), float(far), int(dem.ACCEL_LANE), float(accel_end),
        np.empty((dem.N_LANES, n_v), np.int64), np.empty(dem.N_LANES, np.int64), np.empty(n_v, np.int64), *out)
    return out


def _kernel():
    """:mod:`._fast_lanes`, or ``None`` (numba missing, or ``SAFELANE_NO_NUMBA=1``)."""
    if fast_kernel() is None:
        return None
    from . import _fast_lanes

    return _fast_lanes
