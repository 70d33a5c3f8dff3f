"""The record of the vehicles besides F, the chain and L0 (:class:`Others`), which :mod:`.world` folds into the
paper's roles; its fields, frame and padding are described there."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: ``announce_lane`` of a vehicle that announces no lane change.
NO_LANE = int(np.iinfo(np.int64).min)

_FLOATS = ("x", "y", "vx", "vy", "announce_t")


@dataclass(frozen=True)
class Others:
    """Other vehicles, ``(B, K)`` arrays in the shield's frame (module docstring).

    Attributes:
        x, y: centre position [m]; ``x = +inf`` marks a padding slot (no vehicle).
        vx, vy: velocity [m/s] (``vx >= 0``; ``vy`` positive toward the target lane).
        connected: the vehicle's V2X messages are fresh (it is trusted to announce its lane changes).
        announce_lane: the lane a connected vehicle announced it will enter (shield lanes: 0 original, 1 target,
            2 beyond, −1 the other side), or :data:`NO_LANE`.
        announce_t: the announced earliest start of that lane change [s] (ignored without an announcement).
    """

    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    connected: np.ndarray
    announce_lane: np.ndarray
    announce_t: np.ndarray

    @classmethod
    def from_arrays(cls, x, y, vx, vy, connected=False, announce_lane=NO_LANE, announce_t=np.inf, *, frame=None,
                    batch: int | None = None) -> Others:  # fmt: skip
        """A record from arrays ``(B, K)`` or ``(K,)`` (``B = 1``) that broadcast; ``y``, ``vy`` in a simulator's
        frame mapped by ``frame`` (a :class:`~.situation.LaneFrame`; ``None``: already the shield's). ``batch``:
        broadcast to that many rows. Not validated here (:meth:`validate`, which the Situation calls)."""
        x = np.atleast_2d(np.asarray(x, float))
        y, vy = np.asarray(y, float), np.asarray(vy, float)
        if frame is not None:
            y, vy = frame.y(y, vy)
        arrays = [x, np.atleast_2d(y), np.atleast_2d(np.asarray(vx, float)), np.atleast_2d(vy)]
        conn = np.atleast_2d(np.asarray(connected))
        lane = np.atleast_2d(np.asarray(announce_lane))
        at = np.atleast_2d(np.asarray(announce_t, float))
        shape = np.broadcast_shapes(*(a.shape for a in (*arrays, conn, lane, at)))
        if batch is not None:
            shape = (batch, shape[1])
        out = [np.broadcast_to(a, shape).copy() for a in (*arrays, conn, lane, at)]
        return cls(*out)

    @classmethod
    def empty(cls, batch: int, k: int = 0) -> Others:
        """``k`` padding slots per row."""
        pad = np.full((batch, k), np.inf)
        zero = np.zeros((batch, k))
        return cls(pad, zero, zero.copy(), zero.copy(), np.zeros((batch, k), bool), np.full((batch, k), NO_LANE),
                   np.full((batch, k), np.inf))  # fmt: skip

    @property
    def shape(self) -> tuple:
        return np.shape(self.x)

    def validate(self, batch: int, where: str = "Situation.others") -> None:
        """Raise a ``ValueError`` naming the field, the first bad ``[row, slot]`` and its value."""
        x = self.x
        if not isinstance(x, np.ndarray) or x.ndim != 2 or x.shape[0] != batch:
            raise ValueError(f"{where}.x must have shape ({batch}, K); got {np.shape(x)}")
        for name in ("y", "vx", "vy", "connected", "announce_lane", "announce_t"):
            if np.shape(getattr(self, name)) != x.shape:
                raise ValueError(f"{where}.{name} must have shape {x.shape}; got {np.shape(getattr(self, name))}")
        for name in _FLOATS:
            if np.asarray(getattr(self, name)).dtype.kind not in "fiu":
                raise ValueError(f"{where}.{name} must be numbers; got dtype {np.asarray(getattr(self, name)).dtype}")
        if self.connected.dtype != bool:
            raise ValueError(f"{where}.connected must be booleans; got dtype {self.connected.dtype}")
        if self.announce_lane.dtype.kind not in "iu":
            raise ValueError(f"{where}.announce_lane must be integers (NO_LANE for none); got dtype "
                             f"{self.announce_lane.dtype}")  # fmt: skip
        _first_bad(where, "x", x, np.isnan(x) | np.isneginf(x), "finite, or +inf for padding")
        present = np.isfinite(x)
        for name in ("y", "vx", "vy"):
            arr = getattr(self, name)
            _first_bad(where, name, arr, ~np.isfinite(arr), "finite")
        _first_bad(where, "vx", self.vx, self.vx < 0, ">= 0 (vehicles do not reverse)")
        announced = self.announce_lane != NO_LANE
        _first_bad(where, "announce_lane", self.announce_lane, present & announced & ~self.connected,
                   f"{NO_LANE} (NO_LANE) for a vehicle that is not connected (only V2X announces)")  # fmt: skip
        _first_bad(where, "announce_t", self.announce_t, present & announced & ~np.isfinite(self.announce_t),
                   "finite where a lane change is announced")  # fmt: skip


def _first_bad(where: str, name: str, arr, bad, allowed: str) -> None:
    if np.any(bad):
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{where}.{name}[{row}, {col}] must be {allowed}; got {np.asarray(arr)[row, col].item()!r}")


__all__ = ["NO_LANE", "Others"]
