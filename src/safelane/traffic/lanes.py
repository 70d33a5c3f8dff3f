"""Who is where, lane by lane, for a batch of lane changes: every vehicle's memberships of the mainline lanes in
one sorted array, so that the neighbours of all changers in all lanes are a few array operations
(:meth:`.equipped.LaneChanges.situation`), with no loop over lanes, changers or vehicles.

A vehicle belongs to every lane its body overlaps (one for a vehicle inside its lane, two for one across a lane
boundary; none on the ramp). Memberships are sorted by lane, then by position along the road, ties in fleet order.
Positions enter as their dense ranks (equal positions, equal ranks), so that the sort key ``lane·(V+1) + rank`` is an
exact integer and a search for a changer's position finds the vehicles strictly behind it (``"left"``) or ahead of it
(``"right"``) exactly as a search among the lane's positions would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import demand as dem


@dataclass(frozen=True)
class Memberships:
    """Every (vehicle, lane) membership, sorted by lane then position. ``P`` memberships, ``V`` vehicles."""

    key: np.ndarray  # (P,) lane·stride + rank of the position, ascending
    veh: np.ndarray  # (P,) the fleet index of each membership
    lane: np.ndarray  # (P,) its lane
    start: np.ndarray  # (N_LANES + 1,) where each lane's memberships start (the last entry: P)
    rank: np.ndarray  # (V,) dense rank of each vehicle's position
    stride: int

    @classmethod
    def of(cls, lane, y, x, half: float) -> Memberships:
        """``lane``: each vehicle's lane (``-1`` on the ramp: no membership); ``y``: its road ``y``; ``x``: its
        position along the road; ``half``: a body overlaps lane ``g`` when its centre is within ``half`` of the
        lane's centre."""
        inside = (np.asarray(lane) >= 0)[:, None] & (np.abs(y[:, None] - dem.lane_y(np.arange(dem.N_LANES))) < half)
        veh, g = np.nonzero(inside)  # vehicle-major: within a lane, fleet order
        _, rank = np.unique(x, return_inverse=True)
        stride = len(x) + 1
        key = g * stride + rank[veh]
        order = np.argsort(key, kind="stable")
        key = key[order]
        start = np.searchsorted(key, np.arange(dem.N_LANES + 1) * stride)
        return cls(key, veh[order], g[order], start, rank.reshape(-1), stride)

    def search(self, lane, vehicles, side: str) -> np.ndarray:
        """For each ``(lane[r], vehicles[r])``: the position among the memberships of the first one of that lane at
        (``"left"``) or beyond (``"right"``) the vehicle's position."""
        return np.searchsorted(self.key, lane * self.stride + self.rank[vehicles], side)

    def vehicle(self, pos) -> np.ndarray:
        """The fleet index at membership positions ``pos`` (clipped into range; mask the ones out of their lane)."""
        return self.veh[np.minimum(pos, len(self.veh) - 1)] if len(self.veh) else np.zeros(np.shape(pos), np.int64)

    def fastest_back(self, v, stays) -> np.ndarray:
        """``(P,)``: at each membership, the highest speed ``v`` (per vehicle) from it back to the nearest
        membership at or behind it in its lane for which ``stays`` (per membership) holds, or back to the lane's
        last vehicle where none does. Exact: a running maximum of integer ranks, restarted where a group starts."""
        if not len(self.veh):
            return np.zeros(0)
        first = np.zeros(len(self.veh), bool)
        first[self.start[:-1][self.start[:-1] < len(self.veh)]] = True
        group = np.cumsum(stays | first) - 1
        speeds, rank = np.unique(v[self.veh], return_inverse=True)
        n = len(speeds)
        return speeds[np.maximum.accumulate(group * n + rank.reshape(-1)) - group * n]
