"""The closed loop on the log's batch: every event's frame (:func:`lane_frame`: origin, sign and width of the lanes it
crosses), its first frame (``lead_s`` before the human's crossing, no earlier than the human's run in its original lane)
and the recorded arrays of all events on one clock (:func:`log_batch`), for :mod:`.log_loop` to drive."""

from __future__ import annotations

import numpy as np

from ..tolerances import TIME_TOL_S
from .events import LaneChangeEvent, event_frames
from .recording import Recording


def lane_frame(recording: Recording, event: LaneChangeEvent):
    """``(origin_y, sign, lane_w)``: the original lane's centre, ``+1`` if the target lane is on the left (larger
    ``y``), and the distance between the two lanes' centres [m]; ``y_frame = sign · (y − origin_y)``."""
    lanes = recording.lanes
    c_from, c_to = float(lanes.centre(event.from_lane)), float(lanes.centre(event.to_lane))
    return c_from, (1.0 if c_to > c_from else -1.0), abs(c_to - c_from)


def _start_frame(rec: Recording, ev: LaneChangeEvent, lead: int) -> int:
    """``lead`` frames before the crossing, but not before the human's run in its original lane (valid) began."""
    k = ev.crossing_frame - 1
    while k - 1 >= max(ev.crossing_frame - lead, 0) and rec.valid[ev.vehicle, k - 1] and \
            rec.lane[ev.vehicle, k - 1] == ev.from_lane:  # fmt: skip
        k -= 1
    return k


def log_batch(pairs, *, lead_s: float = 3.0, horizon_s: float = 8.0, dt: float = 0.1) -> dict:
    """All events of ``pairs`` (``[(recording, events), ...]``) on one clock: frame ``k`` of event ``b`` is its start
    plus ``k·dt``. Returns a dict of arrays: ``x, y, v, valid (B, V, K+1)`` of the replayed vehicles (lane frame,
    metres; the changing vehicle itself left out), ``length, width (B, V)``, ``ego (B, 4)`` the start state,
    ``ego_length, ego_width, lane_w (B,)``, ``gap_f, gap_l (B,)`` slots of the human's gap (``-1``: none),
    ``steps (B,)`` the periods the recording covers, ``human_t (B,)`` the human's crossing from the start, and the
    identifying columns."""
    rows = []
    for rec, events in pairs:
        if abs(rec.dt - dt) > TIME_TOL_S:
            raise ValueError(f"{rec.source}: recorded every {rec.dt} s; the closed loop needs the shield's dt = {dt}")
        if not events:
            continue
        at_crossing = event_frames(rec, events, before_s=0.0, after_s=0.0, n_leaders=1)
        gap = {int(e): (int(f), int(lead[0])) for e, f, lead in zip(at_crossing.event, at_crossing.follower,
                                                                    at_crossing.leaders, strict=True)}  # fmt: skip
        for i, ev in enumerate(events):
            rows.append((rec, ev, *gap.get(i, (-1, -1))))
    n_frames = round(horizon_s / dt)
    v_max = max((rec.n_vehicles for rec, *_ in rows), default=1)
    b = len(rows)
    out = {name: np.full((b, v_max, n_frames + 1), np.nan) for name in ("x", "y", "v")}
    out["valid"] = np.zeros((b, v_max, n_frames + 1), bool)
    out["length"], out["width"] = np.ones((b, v_max)), np.ones((b, v_max))
    for name in ("ego_length", "ego_width", "lane_w", "human_t", "start_t"):
        out[name] = np.zeros(b)
    out["ego"] = np.zeros((b, 4))
    out["ids"] = np.full((b, v_max), -1, np.int64)
    out["steps"], out["gap_f"], out["gap_l"] = (np.zeros(b, np.int64) for _ in range(3))
    out["source"], out["vehicle_id"], out["crossing_t"] = [], np.zeros(b, np.int64), np.zeros(b)
    lead = round(lead_s / dt)
    for i, (rec, ev, gf, gl) in enumerate(rows):
        k0 = _start_frame(rec, ev, lead)
        origin, sign, lane_w = lane_frame(rec, ev)
        frames = np.arange(k0, k0 + n_frames + 1)
        inside = frames < rec.n_frames
        fr = np.minimum(frames, rec.n_frames - 1)
        n = rec.n_vehicles
        out["x"][i, :n] = rec.x[:, fr]
        out["y"][i, :n] = sign * (rec.y[:, fr] - origin)
        out["v"][i, :n] = np.maximum(rec.speed[:, fr], 0.0)
        out["valid"][i, :n] = rec.valid[:, fr] & inside[None, :]
        out["valid"][i, ev.vehicle] = False
        out["length"][i, :n], out["width"][i, :n] = rec.length, rec.width
        out["ids"][i, :n] = rec.vehicle_ids
        h = ev.vehicle
        vy = sign * rec.lateral_speed()[h, k0]
        out["ego"][i] = (rec.x[h, k0], sign * (rec.y[h, k0] - origin), np.sqrt(max(rec.speed[h, k0] ** 2 - vy**2,
                                                                                  0.0)), vy)  # fmt: skip
        out["ego_length"][i], out["ego_width"][i], out["lane_w"][i] = rec.length[h], rec.width[h], lane_w
        out["gap_f"][i], out["gap_l"][i] = gf, gl
        out["steps"][i] = min(n_frames, rec.n_frames - 1 - k0)
        out["human_t"][i] = (ev.crossing_frame - k0) * dt
        out["start_t"][i] = rec.t[k0]
        out["source"].append(rec.source)
        out["vehicle_id"][i], out["crossing_t"][i] = ev.vehicle_id, ev.crossing_t
    return out
