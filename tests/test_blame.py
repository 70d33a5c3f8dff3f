"""The blame rule (safelane.blame): hand-computed cases for every clause, the running form against the trajectory
form, batch shapes, bad input.

Parameters of the hand computations (:data:`RSS`): ρ 0.5 s for both, ``accel_max`` 2, ``brake_min`` 6, ``brake_max``
8, lateral 1 / 2 m/s², μ 0.1 m. Two vehicles at 20 m/s one behind the other need
``20·0.5 + 2·0.5²/2 + 21²/(2·6) − 20²/(2·8) = 10 + 0.25 + 36.75 − 25 = 22 m`` bumper to bumper; a 30 m/s rear
vehicle behind a 20 m/s one ``15 + 0.25 + 31²/12 − 25 = 70.333… m``. Two laterally still vehicles need
``2·(1·0.5²/2 + 0.5²/(2·2)) + 0.1 = 0.475 m`` edge to edge; one moving toward the other at 1 m/s
``(0.5 + 0.125 + 1.5²/4) + 0.1875 + 0.1 = 1.475 m``. Vehicles 5 m × 2 m, lanes 3.5 m apart (1.5 m edge to edge).
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane.baselines.rss import RssParams
from safelane.blame import (
    BOTH,
    CLAUSES,
    EGO,
    NONE,
    OTHER,
    Blame,
    Track,
    blame,
    pair_safety,
    start,
    update,
    verdict,
)
from safelane.errors import InputError

RSS = RssParams(response_time_ego=0.5, response_time_other=0.5, accel_max=2.0, brake_min=6.0, brake_max=8.0,
                brake_min_correct=3.0, lat_accel_max=1.0, lat_brake_min=2.0, lateral_fluctuation_margin=0.1)
DT = 0.1
T = np.round(np.arange(0, 121) * DT, 10)  # 0 … 12 s
LANE = 3.5


def track(x, y, vx, vy):
    return Track(np.asarray(x, float), np.asarray(y, float), np.asarray(vx, float), np.asarray(vy, float), 5.0, 2.0)


def cruise(x0, v, y=0.0, t=T):
    return track(x0 + v * t, np.full_like(t, y), np.full_like(t, v), np.zeros_like(t))


def lane_change(x0, v, y0, vy, t_start, t=T, y_end=None):
    """Cruising at ``v``; from ``t_start`` on moving laterally at ``vy`` (the speed jumps: a hand-made record), up to
    ``y_end`` (default: on and on)."""
    y = y0 + vy * np.maximum(t - t_start, 0.0)
    if y_end is not None:
        y = np.minimum(y, y_end) if vy > 0 else np.maximum(y, y_end)
    moving = (t >= t_start - 1e-9) & (y != y_end)
    return track(x0 + v * t, y, np.full_like(t, v), np.where(moving, vy, 0.0))


def braking(x0, v, t_start, decel, t=T):
    """Cruising at ``v``, from ``t_start`` braking at ``decel`` to a stop."""
    tau = np.clip(t - t_start, 0.0, v / decel)
    x = x0 + v * np.minimum(t, t_start) + v * tau - 0.5 * decel * tau * tau
    return track(x, np.zeros_like(t), v - decel * tau, np.zeros_like(t))


def first_contact(ego: Track, other: Track, t=T):
    """The first sample at which the bodies overlap (the hand-made scene's collision)."""
    hit = (np.abs(ego.x - other.x) < 5.0) & (np.abs(ego.y - other.y) < 2.0)
    assert hit.any(), "the scene has no collision"
    return float(t[np.argmax(hit)])


def judge(ego, other, **kw):
    out = blame(T, ego, other, first_contact(ego, other), RSS, **kw)
    return out.labels()[()], out.clause_names()[()], float(out.blame_t)


# ---------------------------------------------------------------- the safe distances (step 1)
def test_pair_safety_golden_distances():
    one = lambda gap, dy=0.0, vy=0.0: pair_safety(  # noqa: E731
        track(0.0, 0.0, 20.0, 0.0), track(5.0 + gap, dy, 20.0, vy), RSS)
    assert one(22.002)[0] and not one(21.9995)[0]  # 22 m, greater by the 1 mm precision
    rear_fast = pair_safety(track(0.0, 0.0, 20.0, 0.0), track(-5.0 - 70.335, 0.0, 30.0, 0.0), RSS)
    assert rear_fast[0] and not pair_safety(track(0.0, 0.0, 20.0, 0.0), track(-5.0 - 70.33, 0.0, 30.0, 0.0), RSS)[0]
    # lateral: 1.5 m edge to edge against 0.475 (still) and 1.475 (the other moving toward the ego at 1 m/s)
    assert one(0.0, LANE)[1] and one(0.0, LANE, -1.0)[1] and not one(0.0, 3.0 + 0.474, -1.0)[1]
    assert not one(0.0, 2.0 + 0.4745)[1] and one(0.0, 2.0 + 0.4765)[1]
    assert one(0.0, 0.5)[2] and not one(0.0, LANE)[2]  # the bodies overlap laterally


# ---------------------------------------------------------------- clause: longitudinal (rear-end in one lane)
def rear_end_by_faster_follower():
    """The ego cruises at 20 m/s; the other, 100 m behind (95 m bumper to bumper) at 30 m/s, runs into it."""
    return cruise(0.0, 20.0), cruise(-100.0, 30.0)


def test_rear_end_the_rear_vehicle_is_responsible():
    ego, other = rear_end_by_faster_follower()
    # safe while 95 − 10 t > 70.333 + 0.001: the last safe sample is t = 2.4 s
    assert judge(ego, other) == ("other", "longitudinal", pytest.approx(2.4))
    assert judge(other, ego) == ("ego", "longitudinal", pytest.approx(2.4))  # roles swapped: the ego rear-ended


def test_rear_end_too_close_from_the_start_is_never_safe_and_the_rear_vehicles():
    ego, other = cruise(0.0, 20.0), cruise(-40.0, 30.0)  # 35 m < 70.3 m from the first sample on
    assert judge(ego, other) == ("other", "never_safe", pytest.approx(np.nan, nan_ok=True))


# ---------------------------------------------------------------- clause: lateral (cut-in)
def close_cut_in_ahead_of_ego():
    """The ego at 22 m/s; the other, 3 m ahead (bumper to bumper; 30.3 m needed) at 20 m/s in the next lane, moves
    into the ego's lane at 1 m/s from t = 1 s."""
    return cruise(0.0, 22.0), lane_change(8.0, 20.0, LANE, -1.0, 1.0)


def test_cut_in_without_safe_distance_the_mover_is_responsible():
    ego, other = close_cut_in_ahead_of_ego()
    # at t = 1.0 the lateral gap 1.5 m exceeds 1.475 m (moving); at 1.1 s it is 1.4 m: the blame time is 1.0 s
    assert judge(ego, other) == ("other", "lateral", pytest.approx(1.0))
    assert judge(other, ego) == ("ego", "lateral", pytest.approx(1.0))  # roles swapped: the ego cut in


def test_cut_in_at_a_safe_distance_then_rear_end_is_the_rear_vehicles():
    """The other merges 95 m ahead (safe: 55 m) and the ego, faster, runs into it later: the longitudinal clause,
    the ego (rear) responsible — not the vehicle that changed lanes."""
    ego = cruise(0.0, 25.0)
    other = lane_change(100.0, 15.0, LANE, -2.0, 0.5, y_end=0.0)
    who, clause, _ = judge(ego, other)
    assert (who, clause) == ("ego", "longitudinal")


def test_simultaneous_lateral_moves_both():
    ego = lane_change(0.0, 22.0, 0.0, 1.0, 1.0)
    other = lane_change(8.0, 20.0, LANE, -1.0, 1.0)
    who, clause, t_b = judge(ego, other)
    assert (who, clause) == ("both", "lateral") and t_b < 1.0 + 1e-9


def test_drift_within_fluctuation_margin_is_not_a_move():
    """The ego drifts 0.04 m toward the other (under μ/2 = 0.05 m) while the other cuts in: the other alone."""
    ego = lane_change(0.0, 22.0, 0.0, 0.02, 0.0)
    ego = ego._replace(y=np.minimum(ego.y, 0.04), vy=np.where(ego.y < 0.04, 0.02, 0.0))
    _, other = close_cut_in_ahead_of_ego()
    assert judge(ego, other)[:2] == ("other", "lateral")


# ---------------------------------------------------------------- clause: front_braked
def front_brakes_at(decel):
    """The ego 32 m (bumper to bumper) behind the other at 20 m/s, both in one lane, safe (22 m); from t = 1 s the
    other brakes at ``decel`` to a stop and the ego does not brake."""
    return cruise(0.0, 20.0), braking(37.0, 20.0, 1.0, decel)


def test_front_braking_beyond_the_maximum_is_the_fronts():
    assert judge(*front_brakes_at(12.0))[:2] == ("other", "front_braked")


def test_front_braking_at_the_maximum_is_the_rears():
    assert judge(*front_brakes_at(8.0))[:2] == ("ego", "longitudinal")
    ego, other = front_brakes_at(12.0)  # the ego in front braking hard, the other behind: the ego's fault
    assert judge(other, ego)[:2] == ("ego", "front_braked")


def test_hard_braking_before_the_blame_time_does_not_count():
    """The front vehicle brakes at 12 m/s² from 20 to 14 m/s while the pair is still safe, then cruises; the rear
    one (faster) closes in later: the rear's."""
    t = T
    tau = np.clip(t - 0.5, 0.0, 0.5)
    v = 20.0 - 12.0 * tau
    x = 60.0 + 20.0 * np.minimum(t, 0.5) + 20.0 * tau - 6.0 * tau * tau + 14.0 * np.maximum(t - 1.0, 0.0)
    other = track(x, np.zeros_like(t), v, np.zeros_like(t))
    assert judge(cruise(0.0, 20.0), other)[:2] == ("ego", "longitudinal")


# ---------------------------------------------------------------- p_m margins, events, the running form
def test_min_gaps_make_a_pm_violation_dangerous():
    """Two vehicles 35 m apart (bumper to bumper; 22 m needed) at 20 m/s in neighbouring lanes: RSS-safe both ways.
    A p_m event at 5 s: without margins its own sample is the blame time (laterally safe: nobody moved, both);
    with a lateral margin of 2 m (> 1.5 m) only the longitudinal distance is safe (the rear vehicle, the ego);
    with a longitudinal margin of 40 m as well the pair is never safe."""
    ego, other = cruise(0.0, 20.0), cruise(40.0, 20.0, y=LANE)
    out = blame(T, ego, other, 5.0, RSS)
    assert (out.labels()[()], out.clause_names()[()], float(out.blame_t)) == ("both", "lateral", 5.0)
    out = blame(T, ego, other, 5.0, RSS, min_lat_gap_m=2.0)
    assert (out.labels()[()], out.clause_names()[()], float(out.blame_t)) == ("ego", "longitudinal", 5.0)
    out = blame(T, ego, other, 5.0, RSS, min_lat_gap_m=2.0, min_lon_gap_m=40.0)
    assert out.clause_names()[()] == "never_safe" and np.isnan(out.blame_t)


def test_no_event_is_none():
    ego, other = rear_end_by_faster_follower()
    out = blame(T, ego, other, np.nan, RSS)
    assert out.labels()[()] is None and out.clause_names()[()] == "" and np.isnan(out.blame_t)


def test_samples_after_the_event_are_ignored():
    ego, other = rear_end_by_faster_follower()
    early = blame(T, ego, other, 2.0, RSS)  # still safe at 2.0: the blame time is the event's own sample
    assert float(early.blame_t) == pytest.approx(2.0) and early.labels()[()] == "other"


def test_running_form_equals_trajectory_form():
    scenes = [rear_end_by_faster_follower(), close_cut_in_ahead_of_ego(), front_brakes_at(12.0),
              front_brakes_at(8.0)]  # fmt: skip
    for ego, other in scenes:
        t_event = first_contact(ego, other)
        state = start()
        for k in np.flatnonzero(T <= t_event):
            state = update(state, T[k], Track(*(np.asarray(q)[k] if np.ndim(q) else q for q in ego)),
                           Track(*(np.asarray(q)[k] if np.ndim(q) else q for q in other)), RSS)  # fmt: skip
        a, b = verdict(state, RSS), blame(T, ego, other, t_event, RSS)
        assert (a.responsible, a.clause) == (b.responsible, b.clause) and a.blame_t == pytest.approx(b.blame_t)


def stack(scenes):
    return tuple(Track(*(np.stack([np.broadcast_to(getattr(s[i], q), T.shape) for s in scenes])
                         for q in Track._fields)) for i in (0, 1))  # fmt: skip


@pytest.mark.parametrize("batch", [(), (4,), (2, 3)])
def test_batch_shapes_match_one_by_one(batch):
    scenes = [rear_end_by_faster_follower(), close_cut_in_ahead_of_ego(), front_brakes_at(12.0),
              front_brakes_at(8.0), (cruise(0.0, 20.0), cruise(-40.0, 30.0)), rear_end_by_faster_follower()]
    n = int(np.prod(batch, dtype=int))
    chosen = scenes[:n] if n <= len(scenes) else scenes
    ego, other = stack(chosen)
    events = np.array([first_contact(*s) for s in chosen])
    events[-1] = np.nan if n > 1 else events[-1]
    ego, other = (Track(*(q.reshape(*batch, len(T)) for q in tr)) for tr in (ego, other))
    out = blame(T, ego, other, events.reshape(batch), RSS)
    assert out.responsible.shape == out.clause.shape == out.blame_t.shape == batch
    for i, (e, o) in enumerate(chosen):
        one = blame(T, e, o, events[i], RSS)
        assert out.responsible.reshape(-1)[i] == one.responsible and out.clause.reshape(-1)[i] == one.clause


def test_per_pair_body_sizes_and_padding():
    ego, other = stack([rear_end_by_faster_follower(), rear_end_by_faster_follower()])
    other = other._replace(length=np.array([5.0, 15.0]))  # (E,) with (E, T) positions
    x = other.x.copy()
    x[1, :10] = np.nan  # not recorded in the first second
    other = other._replace(x=x)
    out = blame(T, ego, other, [first_contact(*rear_end_by_faster_follower()), 8.0], RSS)
    assert list(out.labels()) == ["other", "other"]
    assert out.blame_t[1] > 1.0 - 1e-9  # the first recorded sample is at 1.0 s


def test_codes_and_labels():
    assert (NONE, EGO, OTHER, BOTH) == (0, 1, 2, 3) and BOTH == EGO | OTHER
    out = Blame(np.array([0, 1, 2, 3], np.int8), np.array([0, 1, 3, 2], np.int8), np.full(4, np.nan))
    assert list(out.labels()) == [None, "ego", "other", "both"]
    assert list(out.ego_responsible) == [False, True, False, True]
    assert list(out.clause_names()) == ["", CLAUSES[1], "lateral", "front_braked"]


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "change, field",
    [
        (lambda e, o, kw: (e._replace(vx=np.where(T > 1, np.nan, e.vx)), o, kw), "ego.vx"),
        (lambda e, o, kw: (e, o._replace(width=-1.0), kw), "other.width"),
        (lambda e, o, kw: (e, o._replace(length=np.inf), kw), "other.length"),
        (lambda e, o, kw: (e, o._replace(y=np.zeros(3)), kw), "ego.x"),
        (lambda e, o, kw: (e, o, {**kw, "t": T[::-1]}), "t"),
        (lambda e, o, kw: (e, o, {**kw, "t": np.float64(1.0)}), "t"),
        (lambda e, o, kw: (e, o, {**kw, "event_t": np.inf}), "event_t"),
        (lambda e, o, kw: (tuple(e), o, kw), "ego"),
    ],
)
def test_bad_input_names_the_field(change, field):
    ego, other = rear_end_by_faster_follower()
    ego, other, kw = change(ego, other, {"t": T, "event_t": 5.0})
    with pytest.raises(InputError, match="blame: ") as info:
        blame(kw["t"], ego, other, kw["event_t"], RSS)
    assert info.value.where == field
    assert field.split(".")[-1] in str(info.value)


def test_pair_tracker_keys_vehicles_by_id():
    """Two vehicles, one rear-ending the ego, the other appearing late beside it: the tracker follows each by its id
    and agrees with the trajectory form; an unknown id is NONE."""
    from safelane.blame import PairTracker

    ego, rear = rear_end_by_faster_follower()
    beside = cruise(0.0, 20.0, y=LANE)
    t_event = first_contact(ego, rear)
    tracker = PairTracker(RSS)
    for k in np.flatnonzero(T <= t_event):
        ids = ["rear", "beside"] if T[k] >= 3.0 else ["rear"]
        now = [Track(*(np.asarray(q)[k] if np.ndim(q) else q for q in tr)) for tr in (ego, rear, beside)]
        others = now[1 : 1 + len(ids)]
        tracker.observe(T[k], now[0], ids, Track(*(np.array([getattr(o, q) for o in others]) for q in Track._fields)))
    out = tracker.verdict(["rear", "beside", "nobody"])
    assert list(out.labels()) == ["other", "both", None]
    assert out.blame_t[0] == pytest.approx(float(blame(T, ego, rear, t_event, RSS).blame_t))
    assert out.blame_t[1] == pytest.approx(t_event)  # laterally safe all along: its own sample
