"""Network measures of a traffic-level run: SUMO's collision list with a responsibility rule, SSM conflicts,
throughput, speed, travel time (docs/traffic.md).

**Responsibility** (:func:`blame`, in the spirit of RSS's "the rear vehicle keeps a safe distance"): in a collision
SUMO names the ``collider`` (the rear vehicle of a rear-end) and the ``victim``. The collider is responsible, unless
the victim **cut in**: it entered a lane (a lane change, SUMO's or the shield's) in front of the collider — the
collider any vehicle behind it in that lane — at most ``CUT_IN_WINDOW_S`` before the collision, with a bumper
gap below the collider's safe distance
``v_r·τ + v_r²/(2·b_r) − v_f²/(2·b_f)`` (``τ = 0.5`` s, ``b_r = 4.5`` m/s² the rear's comfortable braking, ``b_f =
8`` m/s² the front's hardest, ``Params.a_x_d``) at that moment. Then the victim is responsible. A vehicle is in
every lane its body overlaps (:func:`lanes_overlapped`): one across a lane boundary counts in both, entering the
second when its body crosses the line, and as the follower of a vehicle that enters either in front of it. (SUMO's
own drivers do not see it so — without the sublane model SUMO puts a vehicle in the lane of its centre only —, and
its collision list registers a pair only when both centres are in one lane.)
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .demand import LANE_W, N_LANES, SSM_THRESHOLDS, lane_y

CUT_IN_WINDOW_S = 3.0
TAU_S, B_REAR, B_FRONT = 0.5, 4.5, 8.0


def safe_distance(v_rear, v_front) -> np.ndarray:
    """The rear vehicle's safe distance [m] to a front vehicle (see the module docstring)."""
    v_rear, v_front = np.asarray(v_rear, float), np.asarray(v_front, float)
    return np.maximum(v_rear * TAU_S + v_rear**2 / (2 * B_REAR) - v_front**2 / (2 * B_FRONT), 0.0)


def blame(collisions: list[dict], entries: list[dict]) -> list[dict]:
    """Each collision (``t``, ``collider``, ``victim``, …) with ``responsible`` (a vehicle id) and ``rule``
    (``"rear"`` or ``"cut-in"``). ``entries``: lane entries (``t``, ``vid``, ``follower``, ``gap_m``, ``v_follower``,
    ``v_vid``) — a vehicle entering a lane in front of ``follower``."""
    out = []
    for c in collisions:
        cut = [e for e in entries if e["vid"] == c["victim"] and e["follower"] == c["collider"]
               and 0.0 <= c["t"] - e["t"] <= CUT_IN_WINDOW_S
               and e["gap_m"] < float(safe_distance(e["v_follower"], e["v_vid"]))]  # fmt: skip
        rule = "cut-in" if cut else "rear"
        out.append({**c, "responsible": c["victim"] if cut else c["collider"], "rule": rule})
    return out


class Referee:
    """The blame as a run goes. Each period :meth:`observe` reads the fleet's lane entries; :meth:`collided` takes a
    step's new collisions, which the next :meth:`observe` judges (:func:`blame`) with the lane entries that step made:
    a lane change and the collision it causes happen in the same step, and the entry is seen only in the state the
    step left (judged at once, the cut-in was missed and the rear vehicle blamed). ``judged``: the collisions so
    far, with ``responsible`` and ``rule``."""

    def __init__(self, length: float = 4.8, width: float = 1.8):
        self.length, self.width = length, width
        self.entries: list[dict] = []
        self.pending: list[dict] = []
        self.judged: list[dict] = []
        self.prev_lanes: dict = {}

    def observe(self, t: float, fleet) -> list[dict]:
        """The lane entries since the last period (also returned); the pending collisions judged with them."""
        new = lane_entries(t, fleet, self.prev_lanes, self.length, self.width)
        self.entries = [e for e in self.entries if t - e["t"] <= CUT_IN_WINDOW_S] + new
        self.judged += blame(self.pending, self.entries)
        self.pending = []
        return new

    def collided(self, collisions: list[dict]) -> None:
        self.pending += collisions


def ssm_conflicts(path: Path | None, warmup_s: float = 0.0) -> list[dict]:
    """The conflicts of SUMO's SSM output with at least one measure past its threshold (:data:`SSM_THRESHOLDS`),
    begun after ``warmup_s``: ``ego``, ``foe``, ``begin``, ``ttc``, ``drac``, ``pet`` (nan where not measured)."""
    if path is None or not Path(path).exists() or Path(path).stat().st_size == 0:
        return []
    out = []
    for conflict in ET.parse(path).getroot().iter("conflict"):
        if float(conflict.get("begin")) < warmup_s:
            continue
        row = {"ego": conflict.get("ego"), "foe": conflict.get("foe"), "begin": float(conflict.get("begin"))}
        for tag, key in (("minTTC", "ttc"), ("maxDRAC", "drac"), ("PET", "pet")):
            el = conflict.find(tag)
            value = el.get("value") if el is not None else None
            row[key] = float(value) if value not in (None, "NA", "") else np.nan
        th = SSM_THRESHOLDS
        if row["ttc"] < th["TTC"] or row["drac"] > th["DRAC"] or row["pet"] < th["PET"]:
            out.append(row)
    return out


class Tally:
    """Running sums of one run after the warm-up: speeds, departures, arrivals, travel times."""

    def __init__(self, warmup_s: float):
        self.warmup_s = warmup_s
        self.v_sum, self.v_n = 0.0, 0
        self.depart: dict[str, float] = {}
        self.travel: list[float] = []
        self.arrived = 0
        self.inserted = 0

    def speeds(self, t: float, v: np.ndarray) -> None:
        if t >= self.warmup_s:
            self.v_sum += float(v.sum())
            self.v_n += len(v)

    def departed(self, t: float, vids) -> None:
        for vid in vids:
            self.depart[vid] = t
            self.inserted += 1

    def arrivals(self, t: float, vids) -> None:
        for vid in vids:
            t0 = self.depart.pop(vid, np.nan)
            if t >= self.warmup_s:
                self.arrived += 1
                if t0 >= self.warmup_s:
                    self.travel.append(t - t0)

    @property
    def mean_speed(self) -> float:
        return self.v_sum / self.v_n if self.v_n else np.nan


def lanes_overlapped(fleet, width: float = 1.8) -> np.ndarray:
    """``(V, N_LANES)``: the lanes (from the left) each vehicle's body overlaps — one for a vehicle inside its lane,
    two for one across a lane boundary (an equipped vehicle changing lanes), none on the ramp. ``width``: the
    vehicles' width [m] (``Params.vehicle_width``)."""
    g = np.arange(N_LANES)
    on_road = (np.asarray(fleet.lane) >= 0)[:, None]
    centre_dist = np.abs(np.asarray(fleet.y, float)[:, None] - lane_y(g)[None, :])
    return on_road & (centre_dist < 0.5 * (LANE_W + width) - 1e-6)


def lane_entries(t: float, fleet, prev_lanes: dict[str, int], length: float = 4.8, width: float = 1.8) -> list[dict]:
    """The vehicles that entered a lane (from the left) since the last period, each with the nearest vehicle behind
    it in that lane (``follower``), their bumper gap and speeds; ``prev_lanes`` (each vehicle's lanes at the last
    period, a bit mask) is updated. A vehicle is in every lane its body overlaps (:func:`lanes_overlapped`): one
    across a lane boundary counts in both, as an entering vehicle and as a follower — a vehicle that moves into a
    lane in front of it cuts in even where its centre is on the other side of the boundary. A vehicle enters a lane
    when its body first overlaps it; a vehicle coming from the ramp enters no lane (it joins the acceleration lane
    from its own)."""
    over = lanes_overlapped(fleet, width)
    mask = (over * (1 << np.arange(N_LANES))[None, :]).sum(1) if len(over) else np.zeros(0, np.int64)
    old = np.array([prev_lanes.get(vid, -1) for vid in fleet.ids], np.int64)
    for vid, m in zip(fleet.ids, mask.tolist(), strict=True):
        prev_lanes[vid] = m if m else -1
    out = []
    x = np.asarray(fleet.x, float)
    entered = mask & ~np.maximum(old, 0)  # lanes overlapped now and not at the last period (bit masks)
    v = np.asarray(fleet.v, float)
    for i in np.flatnonzero((old > 0) & (entered > 0)).tolist():
        for g in np.flatnonzero((entered[i] >> np.arange(N_LANES)) & 1).tolist():
            same = np.flatnonzero(over[:, g] & (x < x[i]))
            if not len(same):
                continue
            gap = x[i] - x[same] - length
            # the nearest behind, and every other one behind whose safe distance the entry broke (RSS: a vehicle
            # enters a lane at the safe distance of *each* vehicle of that lane, not only of the nearest one)
            near = np.argmax(x[same])
            for k in np.flatnonzero((np.arange(len(same)) == near) | (gap < safe_distance(v[same], v[i]))).tolist():
                j = same[k]
                out.append({"t": t, "vid": fleet.ids[i], "lane": int(g), "follower": fleet.ids[j],
                            "gap_m": float(gap[k]), "v_follower": float(v[j]), "v_vid": float(v[i])})  # fmt: skip
    return out
