"""Lane changes found in hand-built recordings, and the open-loop replay's verdicts on obvious cases."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.recorded import Lanes, Recording, event_frames, find_lane_changes
from safelane.recorded.recording import NO_LANE
from safelane.recorded.replay import ReplaySettings, replay

DT = 0.1
LANE_W = 3.5


def two_lanes() -> Lanes:
    """Lane 1 (left, centre y = 3.5) and lane 2 (right, centre y = 0)."""
    return Lanes(ids=np.array([1, 2]), y_right=np.array([1.75, -1.75]), y_left=np.array([5.25, 1.75]),
                 left=np.array([NO_LANE, 1]), right=np.array([2, NO_LANE]), x_start=np.full(2, -np.inf),
                 x_end=np.full(2, np.inf))  # fmt: skip


def recording(x: np.ndarray, y: np.ndarray, speed: np.ndarray) -> Recording:
    """A recording of ``(V, T)`` trajectories on :func:`two_lanes` (lane ids from ``y``), every car 4.5 m long."""
    lanes = two_lanes()
    lane = np.where(y >= 1.75, 1, 2)
    v, t = x.shape
    return Recording(source="hand-built", dt=DT, t0=0.0, vehicle_ids=np.arange(10, 10 + v), x=x, y=y, speed=speed,
                     accel=np.zeros((v, t)), lane=lane, length=np.full(v, 4.5), width=np.full(v, 1.8),
                     valid=np.ones((v, t), bool), lanes=lanes, frame="test")  # fmt: skip


def lateral_profile(t, start_s, duration_s=4.0, to=LANE_W):
    """A smooth (cosine) lateral move from 0 to ``to`` between ``start_s`` and ``start_s + duration_s``."""
    u = np.clip((t - start_s) / duration_s, 0.0, 1.0)
    return to * 0.5 * (1 - np.cos(np.pi * u))


def left_change_with(f_gap_m: float, f_speed: float, l1_gap_m: float, speed=20.0, frames=100):
    """The ego (row 0) moves from lane 2 to lane 1 between t = 3 s and 7 s (crossing at 5 s); F (row 1) and L1 (row 2)
    drive in lane 1 at ``f_gap_m`` behind and ``l1_gap_m`` ahead of it (centre to centre) at the start."""
    t = np.arange(frames) * DT
    ego_x = speed * t
    x = np.stack([ego_x, -f_gap_m + f_speed * t, l1_gap_m + speed * t])
    y = np.stack([lateral_profile(t, 3.0), np.full(frames, LANE_W), np.full(frames, LANE_W)])
    v = np.stack([np.full(frames, speed), np.full(frames, f_speed), np.full(frames, speed)])
    return recording(x, y, v)


def test_a_lane_change_is_found_at_the_line():
    rec = left_change_with(60.0, 20.0, 60.0)
    (event,) = find_lane_changes(rec)
    crossing = np.flatnonzero(rec.y[0] >= 1.75)[0]
    assert (event.vehicle, event.crossing_frame, event.from_lane, event.to_lane) == (0, crossing, 2, 1)
    assert event.to_left and event.line_y == pytest.approx(1.75)
    fr = event_frames(rec, [event], before_s=1.0, after_s=0.5)
    assert len(fr) == 16 and (fr.follower == 1).all() and (fr.leaders[:, 0] == 2).all()
    assert (fr.leaders[:, 1] == -1).all() and (fr.own_leader == -1).all()


def test_crossing_back_within_a_second_is_no_lane_change():
    t = np.arange(100) * DT
    # onto the line and over it for 0.5 s, then back
    y = np.where((t >= 4.0) & (t < 4.5), 2.0, 0.0)[None]
    rec = recording((20.0 * t)[None], y, np.full((1, 100), 20.0))
    assert find_lane_changes(rec) == []
    # held 1 s on the other side: a lane change (and none back: only 0.5 s left in the old lane before the end)
    y = np.where(t >= 4.0, 2.0, 0.0)[None]
    held = recording((20.0 * t)[None], y, np.full((1, 100), 20.0))
    assert [e.crossing_frame for e in find_lane_changes(held)] == [40]
    y = np.where(t >= 9.5, 2.0, 0.0)[None]  # 0.5 s in the new lane before the recording ends
    assert find_lane_changes(recording((20.0 * t)[None], y, np.full((1, 100), 20.0))) == []


def test_an_obviously_safe_gap_is_allowed_at_the_crossing():
    """150 m to F and L1 at equal speeds: above RSS's safe distance behind F at 20 m/s with ad-rss's defaults
    (2 s at up to +3.5 m/s², then 4 m/s² to a stop, against a front vehicle braking at 8 m/s²: about 113 m)."""
    result = replay(left_change_with(f_gap_m=150.0, f_speed=20.0, l1_gap_m=150.0), ReplaySettings(after_s=1.0))
    (event,) = result.events.itertuples()
    assert event.shield_allowed and event.shield_delay_s == pytest.approx(0.0)
    assert event.margin_l1_m > 0 and event.margin_f_m > 0
    assert event.rss_allowed and event.rss_margin_f_m > 0


def test_an_obviously_unsafe_gap_is_not_allowed():
    """F 5 m behind (centre to centre: overlapping bumpers within a metre) and 5 m/s faster: no evasion exists."""
    result = replay(left_change_with(f_gap_m=5.5, f_speed=20.0, l1_gap_m=80.0), ReplaySettings(after_s=1.0))
    (event,) = result.events.itertuples()
    assert not event.shield_allowed and event.margin_f_m < 0
    assert not event.rss_allowed and event.rss_margin_f_m < 0


def test_no_target_lane_vehicle_means_not_replayed():
    rec = left_change_with(60.0, 20.0, 60.0)
    alone = recording(rec.x[:1], rec.y[:1], rec.speed[:1])
    result = replay(alone)
    assert result.events.empty and len(result.skipped) == 1 and "no target-lane vehicle" in result.skipped[0][1]


def test_connectivity_draw_is_seeded():
    rec = left_change_with(30.0, 20.0, 30.0)
    a = replay(rec, ReplaySettings(connected_share=0.5, seed=3)).rows
    b = replay(rec, ReplaySettings(connected_share=0.5, seed=3)).rows
    assert a.equals(b)
    assert not replay(rec, ReplaySettings(connected_share=0.0)).rows["f_connected"].any()
    assert replay(rec, ReplaySettings(connected_share=1.0)).rows["f_connected"].all()
