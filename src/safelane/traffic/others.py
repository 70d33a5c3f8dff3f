"""The traffic co-simulation's feed of the shield's world model (docs/traffic.md, "The world model's feed"):
:func:`others_record`, the vehicles that can enter a changer's path without being F, the chain or ``L0``, as
:class:`~safelane.shield.world.Others` for the whole batch of changers."""

from __future__ import annotations

import numpy as np

from ..shield.world import NO_LANE, Others
from . import demand as dem
from .measures import lanes_overlapped

#: [m] the world model's window: vehicles in the lanes beyond the target lane and on the other side count as others
#: when their centre is at most this far ahead of or behind the changer's (a radar's range; at the 4,900 veh/h of
#: the sweep a lane holds a vehicle every 20–40 m, so F and L1 are well inside it).
OTHERS_WINDOW_M = 150.0
#: The world model's slots per changer: the nearest others (along the road) in the window, both lanes together.
OTHERS_SLOTS = 8


def others_record(changes, fleet, x, rows, t) -> Others:
    """The changers' :class:`~safelane.shield.world.Others` (``(B, OTHERS_SLOTS)``, shield frame;
    ``changes``: the :class:`~.equipped.LaneChanges`): every vehicle whose body overlaps the lane beyond the target
    lane or the lane on the changer's other side and neither its own nor its target lane — so never F, a chain
    member or ``L0``, which are taken from those two lanes by the same body test — with its centre within
    ``others_window_m`` of the changer's, the ``others_slots`` nearest along the road; padding ``x = +inf``. ``x``:
    the fleet's centres with the changers at their exact states (``rows``: their fleet indices). Batched: no loop
    over changers or vehicles."""
    prm = changes.params
    b, k, n_v = len(changes.ids), changes.others_slots, len(fleet.ids)
    step = changes.sign.astype(np.int64)  # +1: a change to the left (toward g - 1)
    target = changes.g0 - step
    # lanes from the left, padded by two lanes of nobody on either side (the beyond/other-side lanes of a
    # changer next to the edge of the road)
    over = np.zeros((n_v, dem.N_LANES + 4), bool)
    over[:, 2:-2] = lanes_overlapped(fleet, prm.vehicle_width)
    col = lambda g: over[:, g + 2].T  # (B, V): vehicle in lane g[r] of row r  # noqa: E731
    near = np.abs(x[None, :] - changes.ex[:, None]) <= changes.others_window_m
    cand = (col(target - step) | col(changes.g0 + step)) & ~col(changes.g0) & ~col(target) & near
    key = np.concatenate([np.where(cand, np.abs(x[None, :] - changes.ex[:, None]), np.inf), np.full((b, k), np.inf)],
                         axis=1)  # fmt: skip
    idx = np.argpartition(key, k - 1, axis=1)[:, :k] if k else np.zeros((b, 0), np.int64)
    idx = np.take_along_axis(idx, np.argsort(np.take_along_axis(key, idx, 1), axis=1, kind="stable"), 1)
    present = np.isfinite(np.take_along_axis(key, idx, 1))
    j = np.where(present, idx, 0)
    sign = changes.sign[:, None]
    vy_road = np.zeros(n_v) if getattr(fleet, "vy", None) is None else np.asarray(fleet.vy, float).copy()
    vy_road[rows] = changes.sign * changes.evy  # the changers: their exact lateral speeds
    conn = present & np.asarray(fleet.equipped, bool)[j]
    # an equipped changer announces the lane it will enter (its target; its own lane while it returns) from its
    # start, in the receiving row's frame (lane i at y = i·w from the row's own lane's centre)
    row_of = np.full(n_v, -1)
    row_of[rows] = np.arange(b)
    c = row_of[j]
    changing = conn & (c >= 0)
    c = np.maximum(c, 0)
    dest = np.where(changes.ret[c], changes.g0[c], target[c])
    lane = step[:, None] * (changes.g0[:, None] - dest)
    changes.counts["others_slots"] += int(present.sum())  # vehicle-rows the record carried (not in cells.csv)
    changes.counts["others_connected"] += int(conn.sum())
    changes.counts["others_announced"] += int(changing.sum())
    y = sign * (fleet.y[j] - dem.lane_y(changes.g0)[:, None])
    return Others(
        x=np.where(present, x[j], np.inf), y=np.where(present, y, 0.0),
        vx=np.where(present, np.maximum(fleet.v[j], 0.0), 0.0), vy=np.where(present, sign * vy_road[j], 0.0),
        connected=conn, announce_lane=np.where(changing, lane, NO_LANE).astype(np.int64),
        announce_t=np.where(changing, changes.t0[c], np.inf),
    )  # fmt: skip
