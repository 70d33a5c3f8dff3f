"""Lane changes in a recording (:func:`find_lane_changes`) and who is around them (:func:`event_frames`).

**What counts as a lane change.** The line is detected as a change of the lane id of the vehicle's reference point
(its centre, :attr:`Recording.lane`): the crossing frame ``c`` is the first frame in the new lane. It is an event
when the vehicle holds the old lane for at least ``hold_s`` (1 s) before ``c`` and the new lane for at least
``hold_s`` from ``c`` on, every frame valid, and the two lanes are neighbours. A vehicle that crosses back within
``hold_s`` made no lane change (nor did one that drifts onto a line and off it).

**Who is around it**, at every frame of a window around the crossing (:func:`event_frames`), relative to the
changing vehicle (the *ego*) and the target lane fixed for the event:

* ``follower``: the nearest target-lane vehicle whose centre is at or behind the ego's (``F``);
* ``leaders``: the nearest ``n_leaders`` target-lane vehicles ahead of it, nearest first (``L1, L2, …``);
* ``own_leader``: the nearest vehicle ahead in the original lane (``L0``);
* ``entrants``: the vehicles that could enter the ego's path: those in the lane on the far side of the target lane
  within ``entrant_window_m`` of the ego, nearest first (one that does enter it is a target-lane vehicle from then
  on, and a follower or leader there).

Indices are vehicle rows of the recording, ``-1`` where there is none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .recording import NO_LANE, Recording

#: Rows of (event-frame × vehicle) comparisons done at once in :func:`event_frames` (bounds the memory).
_CHUNK_CELLS = 4_000_000


@dataclass(frozen=True)
class LaneChangeEvent:
    """One lane change.

    Attributes:
        vehicle: the vehicle's row in the recording; vehicle_id: its id in the source.
        crossing_frame: the first frame with the centre in the new lane; crossing_t: its time [s].
        from_lane, to_lane: lane ids; to_left: the target lane is on the left.
        line_y: the lateral position [m] of the line crossed (recording frame).
    """

    vehicle: int
    vehicle_id: int
    crossing_frame: int
    crossing_t: float
    from_lane: int
    to_lane: int
    to_left: bool
    line_y: float


def _runs(same: np.ndarray, backward: bool) -> np.ndarray:
    """``(V, T)`` length of the run of ``True`` ending (``backward``) or starting at each frame."""
    out = np.zeros(same.shape, np.int64)
    steps = range(same.shape[1]) if backward else range(same.shape[1] - 1, -1, -1)
    prev = np.zeros(same.shape[0], np.int64)
    for k in steps:  # over frames only
        prev = np.where(same[:, k], prev + 1, 0)
        out[:, k] = prev
    return out


def find_lane_changes(recording: Recording, hold_s: float = 1.0) -> list[LaneChangeEvent]:
    """Every lane change of the recording (module docstring), ordered by crossing time then vehicle."""
    rec = recording
    hold = max(round(hold_s / rec.dt), 1)
    lane, valid = rec.lane, rec.valid & (rec.lane != NO_LANE)
    v, t = lane.shape
    # runs of "same lane as the frame before / after, valid": a run ending at c-1 of length >= hold means the old lane
    # was held for hold frames up to c-1; one starting at c means the new lane is held from c on.
    before = np.zeros((v, t), bool)
    before[:, 1:] = valid[:, 1:] & valid[:, :-1] & (lane[:, 1:] == lane[:, :-1])
    held_back = _runs(before, backward=True) + valid  # frames of the run ending here
    after = np.zeros((v, t), bool)
    after[:, :-1] = valid[:, :-1] & valid[:, 1:] & (lane[:, :-1] == lane[:, 1:])
    held_fwd = _runs(after, backward=False) + valid
    change = np.zeros((v, t), bool)
    change[:, 1:] = valid[:, 1:] & valid[:, :-1] & (lane[:, 1:] != lane[:, :-1])
    change[:, 1:] &= (held_back[:, :-1] >= hold) & (held_fwd[:, 1:] >= hold)
    rows, cols = np.nonzero(change)
    old, new = lane[rows, cols - 1], lane[rows, cols]
    to_left = rec.lanes.neighbour(old, True) == new
    neighbours = to_left | (rec.lanes.neighbour(old, False) == new)
    rows, cols, old, new, to_left = (a[neighbours] for a in (rows, cols, old, new, to_left))
    line = rec.lanes.line_between(old, new) if len(rows) else np.zeros(0)
    order = np.lexsort((rows, cols))
    return [
        LaneChangeEvent(int(rows[i]), int(rec.vehicle_ids[rows[i]]), int(cols[i]), float(rec.t[cols[i]]),
                        int(old[i]), int(new[i]), bool(to_left[i]), float(line[i]))
        for i in order
    ]  # fmt: skip


@dataclass(frozen=True)
class EventFrames:
    """Every frame of every event's window, batch first (``R`` rows = event-frames).

    Attributes:
        event: ``(R,)`` index into the events list; frame: ``(R,)`` the recording's frame; t_rel: ``(R,)`` time from
            the event's crossing [s] (negative before it).
        ego: ``(R,)`` the changing vehicle's row.
        follower: ``(R,)``; leaders: ``(R, K)``; own_leader: ``(R,)``; entrants: ``(R, J)``: vehicle rows, ``-1``
            where none (see the module docstring).
        from_lane, to_lane: ``(R,)`` lane ids; to_left: ``(R,)``; line_y: ``(R,)`` the line crossed [m].
    """

    event: np.ndarray
    frame: np.ndarray
    t_rel: np.ndarray
    ego: np.ndarray
    follower: np.ndarray
    leaders: np.ndarray
    own_leader: np.ndarray
    entrants: np.ndarray
    from_lane: np.ndarray
    to_lane: np.ndarray
    to_left: np.ndarray
    line_y: np.ndarray

    def __len__(self) -> int:
        return len(self.event)


def _nearest(key: np.ndarray, k: int) -> np.ndarray:
    """``(R, k)`` column indices of the ``k`` smallest finite keys per row, ``-1`` where fewer."""
    if key.shape[1] == 0:
        return np.full((key.shape[0], k), -1)
    order = np.argsort(key, axis=1, kind="stable")[:, :k]
    found = np.isfinite(np.take_along_axis(key, order, axis=1))
    out = np.where(found, order, -1)
    if out.shape[1] < k:
        out = np.concatenate([out, np.full((out.shape[0], k - out.shape[1]), -1)], axis=1)
    return out


def event_frames(
    recording: Recording,
    events: list[LaneChangeEvent],
    before_s: float = 3.0,
    after_s: float = 3.0,
    n_leaders: int = 3,
    n_entrants: int = 2,
    entrant_window_m: float = 60.0,
) -> EventFrames:
    """The neighbours of each event at every frame in ``[crossing − before_s, crossing + after_s]`` where the ego is
    recorded (module docstring), all event-frames at once."""
    rec = recording
    if not events:
        none = np.zeros(0, np.int64)
        return EventFrames(none, none, np.zeros(0), none, none, np.zeros((0, n_leaders), np.int64), none,
                           np.zeros((0, n_entrants), np.int64), none, none, np.zeros(0, bool), np.zeros(0))  # fmt: skip
    lo, hi = round(before_s / rec.dt), round(after_s / rec.dt)
    offsets = np.arange(-lo, hi + 1)
    ev = np.repeat(np.arange(len(events)), len(offsets))
    ego = np.array([e.vehicle for e in events])[ev]
    crossing = np.array([e.crossing_frame for e in events])[ev]
    frame = crossing + np.tile(offsets, len(events))
    inside = (frame >= 0) & (frame < rec.n_frames)
    inside[inside] = rec.valid[ego[inside], frame[inside]]
    ev, ego, crossing, frame = ev[inside], ego[inside], crossing[inside], frame[inside]
    from_lane = np.array([e.from_lane for e in events])[ev]
    to_lane = np.array([e.to_lane for e in events])[ev]
    to_left = np.array([e.to_left for e in events])[ev]
    far_lane = rec.lanes.neighbour(to_lane, to_left)

    r = len(ev)
    follower = np.empty(r, np.int64)
    own_leader = np.empty(r, np.int64)
    leaders = np.empty((r, n_leaders), np.int64)
    entrants = np.empty((r, n_entrants), np.int64)
    step = max(_CHUNK_CELLS // max(rec.n_vehicles, 1), 1)
    for a in range(0, r, step):  # chunks of rows, every vehicle at once
        sl = slice(a, a + step)
        f, e = frame[sl], ego[sl]
        x, lane, ok = rec.x[:, f].T, rec.lane[:, f].T, rec.valid[:, f].T  # (rows, V)
        ok = ok & (np.arange(rec.n_vehicles)[None, :] != e[:, None])
        dx = x - rec.x[e, f][:, None]
        in_target = ok & (lane == to_lane[sl, None])
        behind = np.where(in_target & (dx <= 0.0), -dx, np.inf)
        ahead = np.where(in_target & (dx > 0.0), dx, np.inf)
        own_ahead = np.where(ok & (lane == from_lane[sl, None]) & (dx > 0.0), dx, np.inf)
        far = (lane == far_lane[sl, None]) & (far_lane[sl, None] != NO_LANE)
        near_far = ok & far & (np.abs(dx) <= entrant_window_m)
        follower[sl] = _nearest(behind, 1)[:, 0]
        leaders[sl] = _nearest(ahead, n_leaders)
        own_leader[sl] = _nearest(own_ahead, 1)[:, 0]
        entrants[sl] = _nearest(np.where(near_far, np.abs(dx), np.inf), n_entrants)
    return EventFrames(
        event=ev, frame=frame, t_rel=(frame - crossing) * rec.dt, ego=ego, follower=follower, leaders=leaders,
        own_leader=own_leader, entrants=entrants, from_lane=from_lane, to_lane=to_lane, to_left=to_left,
        line_y=np.array([e.line_y for e in events])[ev],
    )  # fmt: skip
