"""Recorded traffic: real trajectories loaded into one :class:`Recording` type, their lane changes, and the shield's
open-loop verdicts on them (docs/real_traffic.md).

* loaders: :func:`load_commonroad` (CommonRoad scenario XML; extra ``commonroad``), :func:`load_ngsim` (NGSIM
  trajectory files), :func:`load_npz` / :func:`save_npz` (lossless ``.npz``), :func:`load_recording` (any of them,
  by content);
* :func:`find_lane_changes` → :class:`LaneChangeEvent`; :func:`event_frames` → :class:`EventFrames` (who is
  around each lane change at every 0.1 s);
* :func:`sample_paths`: the three NGSIM US-101 snippets shipped with the package (CommonRoad's conversion);
* :mod:`.replay`: the shield's open-loop verdicts on every lane change (``replay(recording, ReplaySettings())``).
"""

from __future__ import annotations

from .commonroad_reader import load_commonroad
from .events import EventFrames, LaneChangeEvent, event_frames, find_lane_changes
from .ngsim import load_ngsim
from .recording import NO_LANE, Lanes, Recording
from .store import load_npz, load_recording, sample_paths, save_npz

__all__ = [
    "NO_LANE",
    "EventFrames",
    "LaneChangeEvent",
    "Lanes",
    "Recording",
    "event_frames",
    "find_lane_changes",
    "load_commonroad",
    "load_ngsim",
    "load_npz",
    "load_recording",
    "sample_paths",
    "save_npz",
]
