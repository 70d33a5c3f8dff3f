"""One type for recorded traffic: :class:`Recording` (every loader's output) and its :class:`Lanes`.

A recording is a batch of vehicles over a common time base, batch first: every per-vehicle-per-frame array is
``(V, T)`` with a ``valid`` mask (a vehicle is present only in some frames; padding holds ``NaN`` / ``-1``).

The frame is lane-based: ``x`` [m] is the longitudinal position of the vehicle's centre along the road's direction
of travel, ``y`` [m] its lateral position, positive to the **left** of the direction of travel. Each loader says
how it projects its source onto this frame (:mod:`.commonroad_reader`, :mod:`.ngsim`; docs/real_traffic.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Lane id of a vehicle-frame that lies on no known lane (or is padding).
NO_LANE = -1


@dataclass(frozen=True)
class Lanes:
    """The lanes of a recording, as far as the source format gives them (``L`` lanes).

    Attributes:
        ids: ``(L,)`` lane id (the values of :attr:`Recording.lane`).
        y_right, y_left: ``(L,)`` lateral bounds [m] in the recording's frame (``y_right < y_left``); estimated
            where the format has no geometry (NGSIM: from the vehicles' lateral positions).
        left, right: ``(L,)`` the id of the neighbour lane on that side (same direction), ``-1`` where none.
        x_start, x_end: ``(L,)`` the longitudinal stretch [m] where the lane exists (``±inf`` when unknown).
    """

    ids: np.ndarray
    y_right: np.ndarray
    y_left: np.ndarray
    left: np.ndarray
    right: np.ndarray
    x_start: np.ndarray
    x_end: np.ndarray

    def index(self, lane_id) -> np.ndarray:
        """Row of each lane id in these arrays (``-1`` for an unknown id); any shape."""
        lane_id = np.asarray(lane_id)
        order = np.argsort(self.ids)
        pos = np.clip(np.searchsorted(self.ids, lane_id, sorter=order), 0, len(self.ids) - 1)
        rows = order[pos]
        return np.where(self.ids[rows] == lane_id, rows, -1)

    def neighbour(self, lane_id, toward_left) -> np.ndarray:
        """The id of the lane beside ``lane_id`` on the left (``toward_left``) or right; ``-1`` where none."""
        rows = self.index(lane_id)
        side = np.where(np.asarray(toward_left, bool), self.left[rows], self.right[rows])
        return np.where(rows >= 0, side, NO_LANE)

    def line_between(self, from_id, to_id) -> np.ndarray:
        """The lateral position [m] of the line between two neighbour lanes (mean of the two facing bounds)."""
        a, b = self.index(from_id), self.index(to_id)
        to_left = self.y_right[b] > self.y_right[a]
        return np.where(to_left, 0.5 * (self.y_left[a] + self.y_right[b]), 0.5 * (self.y_right[a] + self.y_left[b]))

    def centre(self, lane_id) -> np.ndarray:
        rows = self.index(lane_id)
        return 0.5 * (self.y_left[rows] + self.y_right[rows])


@dataclass(frozen=True)
class Recording:
    """Recorded vehicles over a common time base (``V`` vehicles, ``T`` frames; every array batch first).

    Attributes:
        source: where it was loaded from (a file path, for messages).
        dt: the time step [s] between frames.
        t0: the time [s] of frame 0 (the source's clock: CommonRoad time step × dt, NGSIM Frame_ID × 0.1).
        vehicle_ids: ``(V,)`` the source's vehicle ids.
        x, y: ``(V, T)`` longitudinal and lateral position of the vehicle's centre [m] (lane-based frame, module
            docstring).
        speed: ``(V, T)`` speed [m/s]; accel: ``(V, T)`` longitudinal acceleration [m/s²].
        lane: ``(V, T)`` the id of the lane the centre lies in (:data:`NO_LANE` where none or invalid).
        length, width: ``(V,)`` vehicle size [m].
        valid: ``(V, T)`` the vehicle is recorded in that frame.
        lanes: the lanes (:class:`Lanes`).
        frame: one line saying how the source was projected onto the lane-based frame.
    """

    source: str
    dt: float
    t0: float
    vehicle_ids: np.ndarray
    x: np.ndarray
    y: np.ndarray
    speed: np.ndarray
    accel: np.ndarray
    lane: np.ndarray
    length: np.ndarray
    width: np.ndarray
    valid: np.ndarray
    lanes: Lanes
    frame: str

    @property
    def n_vehicles(self) -> int:
        return self.x.shape[0]

    @property
    def n_frames(self) -> int:
        return self.x.shape[1]

    @property
    def t(self) -> np.ndarray:
        """``(T,)`` the time of each frame [s]."""
        return self.t0 + self.dt * np.arange(self.n_frames)

    def lateral_speed(self) -> np.ndarray:
        """``(V, T)`` lateral speed [m/s]: central differences of ``y`` inside each vehicle's valid frames
        (one-sided at its ends; 0 for a single frame; ``NaN`` where invalid)."""
        return _derivative(self.y, self.valid, self.dt)

    def lateral_accel(self) -> np.ndarray:
        """``(V, T)`` lateral acceleration [m/s²], the same differences applied to :meth:`lateral_speed`."""
        return _derivative(self.lateral_speed(), self.valid, self.dt)


def _derivative(values: np.ndarray, valid: np.ndarray, dt: float) -> np.ndarray:
    """Central differences along the last axis where both neighbours are valid, one-sided where one is."""
    prev_ok = np.zeros_like(valid)
    prev_ok[:, 1:] = valid[:, :-1] & valid[:, 1:]
    next_ok = np.zeros_like(valid)
    next_ok[:, :-1] = valid[:, 1:] & valid[:, :-1]
    prev = np.roll(values, 1, axis=1)
    nxt = np.roll(values, -1, axis=1)
    central = (nxt - prev) / (2.0 * dt)
    forward = (nxt - values) / dt
    backward = (values - prev) / dt
    with np.errstate(invalid="ignore"):
        out = np.where(prev_ok & next_ok, central, np.where(next_ok, forward, np.where(prev_ok, backward, 0.0)))
    return np.where(valid, out, np.nan)


def check_recording(rec: Recording) -> Recording:
    """Shapes agree; valid frames are finite (a loader's last step; raises ``ValueError`` naming the field)."""
    shape = rec.x.shape
    for name in ("y", "speed", "accel", "lane", "valid"):
        if getattr(rec, name).shape != shape:
            raise ValueError(f"Recording.{name} has shape {getattr(rec, name).shape}; expected {shape}")
    for name in ("vehicle_ids", "length", "width"):
        if getattr(rec, name).shape != shape[:1]:
            raise ValueError(f"Recording.{name} has shape {getattr(rec, name).shape}; expected {shape[:1]}")
    for name in ("x", "y", "speed", "accel"):
        if not np.isfinite(getattr(rec, name)[rec.valid]).all():
            raise ValueError(f"Recording.{name} is not finite in a valid frame ({rec.source})")
    return rec
