"""Closed loop on the log (safelane.recorded.log_loop): hand-built recordings where the answer is known, the blame
rule's pieces against independent computations, and the shipped US-101 sample."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.recorded import log_checks as chk
from safelane.recorded.events import find_lane_changes
from safelane.recorded.log_loop import run_log_loop, summary
from safelane.recorded.recording import Lanes, Recording

DT = 0.1
LANE_W = 3.5
T = 100  # frames (10 s)
CROSS = 40  # the human's crossing frame


def _motion(x0, v0, accel):
    """Exact positions and speeds at every frame for piecewise-constant ``accel`` (per frame), stopping at rest."""
    x, v = np.empty(T), np.empty(T)
    x[0], v[0] = x0, v0
    for k in range(1, T):
        a = accel[k - 1]
        t_stop = v[k - 1] / -a if a < 0 else np.inf
        h = min(DT, t_stop)
        x[k] = x[k - 1] + v[k - 1] * h + 0.5 * a * h * h
        v[k] = max(v[k - 1] + a * DT, 0.0) if h == DT else 0.0
    return x, v


def _human_y():
    """The human's lateral path: lane 1 (y = 0) to lane 2 (y = 3.5), a smooth ramp over frames 25-55 (the centre
    crosses the line at y = 1.75 at frame 40)."""
    s = np.clip((np.arange(T) - 25) / 30.0, 0.0, 1.0)
    return LANE_W * (3 * s**2 - 2 * s**3)


def recording(vehicles) -> Recording:
    """A two-lane straight road (lane 1 at y = 0, lane 2 on its left at y = 3.5) with ``vehicles``: dicts of
    ``x0, v0, y`` (a number or a path), ``accel`` (per frame, default 0); the first one is the lane changer."""
    n = len(vehicles)
    x, y, v, a = (np.zeros((n, T)) for _ in range(4))
    for i, veh in enumerate(vehicles):
        acc = np.broadcast_to(np.asarray(veh.get("accel", 0.0), float), (T,))
        x[i], v[i] = _motion(veh["x0"], veh["v0"], acc)
        a[i] = np.where(v[i] > 0, acc, 0.0)
        y[i] = np.broadcast_to(veh["y"], (T,))
    lanes = Lanes(ids=np.array([1, 2]), y_right=np.array([-1.75, 1.75]), y_left=np.array([1.75, 5.25]),
                  left=np.array([2, -1]), right=np.array([-1, 1]), x_start=np.full(2, -np.inf),
                  x_end=np.full(2, np.inf))  # fmt: skip
    return Recording(
        source="hand-built", dt=DT, t0=0.0, vehicle_ids=np.arange(100, 100 + n), x=x, y=y, speed=v, accel=a,
        lane=np.where(y < 1.75, 1, 2), length=np.full(n, 4.8), width=np.full(n, 1.8), valid=np.ones((n, T), bool),
        lanes=lanes, frame="hand-built",
    )  # fmt: skip


def wide_gap() -> Recording:
    """The target lane's follower 60 m back, its leader 60 m ahead, all at 20 m/s: room to spare."""
    return recording([
        dict(x0=0.0, v0=20.0, y=_human_y()),
        dict(x0=-60.0, v0=20.0, y=LANE_W),
        dict(x0=60.0, v0=20.0, y=LANE_W),
    ])  # fmt: skip


def closing_gap() -> Recording:
    """The target lane's leader 14 m ahead of the changer brakes at 6 m/s² (``a_x_d``) to a stop from the moment the
    ego takes over; its follower 25 m back keeps 20 m/s until it must brake for it too (at 6 m/s² from 1.5 s on)."""
    brake = np.where(np.arange(T) >= CROSS - 30, -6.0, 0.0)
    follow = np.where(np.arange(T) >= CROSS - 15, -6.0, 0.0)
    return recording([
        dict(x0=0.0, v0=20.0, y=_human_y()),
        dict(x0=14.0, v0=20.0, y=LANE_W, accel=brake),
        dict(x0=-25.0, v0=20.0, y=LANE_W, accel=follow),
    ])  # fmt: skip


def rear_ram() -> Recording:
    """A replayed follower in the changer's own lane closes from 40 m back at 32 m/s on an ego at 20 m/s, whatever
    the ego does; the target lane is blocked by a vehicle beside it (so the ego cannot leave)."""
    return recording([
        dict(x0=0.0, v0=20.0, y=_human_y()),
        dict(x0=-52.0, v0=32.0, y=0.0),  # 40 m back when the ego takes over (t = 1 s, 3 s before the crossing)
        dict(x0=0.0, v0=20.0, y=LANE_W),
    ])  # fmt: skip


def _run(rec, **kw):
    events = find_lane_changes(rec)
    assert [e.crossing_frame for e in events] == [CROSS]
    return run_log_loop(rec, events, **kw).iloc[0]


def test_wide_gap_completes_like_the_human():
    row = _run(wide_gap())
    assert row["initial_safe"] and row["completed"]
    assert row["human_time_s"] == pytest.approx(3.0)
    assert 0.5 < row["time_s"] < 6.0
    assert not row["collision"] and not row["pm_ego"] and not row["pm_other"]
    assert row["n_abort"] == 0


def test_a_closing_gap_is_refused_without_ego_fault():
    row = _run(closing_gap())
    assert row["n_abort"] + row["n_hesitate"] > 0
    assert not row["collision_ego"] and not row["pm_ego"]


def test_a_replayed_follower_ramming_the_ego_is_its_fault():
    row = _run(rear_ram())
    assert row["collision"] and row["collision_blame"] == "other"
    assert row["collision_with"] == 101
    assert not row["collision_ego"] and not row["pm_ego"]  # nor once the replay has driven on through the ego
    assert not row["completed"]


def test_the_nn_planner_runs_too():
    row = _run(wide_gap(), nominal="mlp")
    assert row["completed"] and not row["collision"]


def test_unknown_connectivity_is_refused():
    with pytest.raises(ValueError, match="connectivity"):
        run_log_loop(wide_gap(), connectivity="all")


# -- the referee's pieces, against independent computations ---------------------------------------------------------


def _corners(x, y, th, length, width):
    c, s = np.cos(th), np.sin(th)
    pts = [(sx * length / 2, sy * width / 2) for sx in (-1, 1) for sy in (-1, 1)]
    return [(x + c * px - s * py, y + s * px + c * py) for px, py in pts]


def _inside(px, py, x, y, th, length, width):
    c, s = np.cos(th), np.sin(th)
    u, w = c * (px - x) + s * (py - y), -s * (px - x) + c * (py - y)
    return abs(u) < length / 2 - 1e-9 and abs(w) < width / 2 - 1e-9


def _overlap_by_points(a, b, n=40):
    """Two rectangles overlap iff a point of one's (densely sampled) area lies inside the other (a sampled check:
    overlaps thinner than the grid may be missed, so only clear cases are compared)."""
    for p, q in ((a, b), (b, a)):
        x, y, th, length, width = p
        for u in np.linspace(-0.5, 0.5, n):
            for w in np.linspace(-0.5, 0.5, n // 4):
                px = x + np.cos(th) * u * length - np.sin(th) * w * width
                py = y + np.sin(th) * u * length + np.cos(th) * w * width
                if _inside(px, py, *q):
                    return True
    return False


def test_boxes_overlap_matches_point_sampling():
    rng = np.random.default_rng(3)
    agree = 0
    for _ in range(300):
        a = (0.0, 0.0, rng.uniform(-0.3, 0.3), 4.8, 1.8)
        b = (rng.uniform(-7, 7), rng.uniform(-3, 3), rng.uniform(-0.3, 0.3), rng.uniform(4, 12), rng.uniform(1.5, 2.6))
        got = bool(chk.boxes_overlap(*a, *b))
        margin = min(abs(b[0]) - (a[3] + b[3]) / 2, abs(b[1]) - (a[4] + b[4]) / 2)
        if abs(margin) < 0.6:  # near touching: the sampled reference is not exact there
            continue
        assert got == _overlap_by_points(a, b), (a, b)
        agree += 1
    assert agree > 100


def test_sample_segments_matches_fine_time_stepping():
    rng = np.random.default_rng(0)
    dur = np.array([[0.03, 0.05, 0.02], [0.1, 0.0, 0.0]])
    ax, ay = rng.uniform(-6, 3, (2, 3)), rng.uniform(-2, 2, (2, 3))
    ego = (np.array([0.0, 5.0]), np.array([0.5, 1.0]), np.array([0.2, 20.0]), np.array([0.3, -0.4]))
    taus = np.array([0.01, 0.04, 0.1])
    x, y, vx, vy = chk.sample_segments(ego, dur, ax, ay, taus)
    for b in range(2):  # explicit Euler at 1 µs steps
        px, py, pvx, pvy, t = ego[0][b], ego[1][b], ego[2][b], ego[3][b], 0.0
        h = 1e-6
        knots = np.cumsum(dur[b])
        for j, tau in enumerate(taus):
            while t < tau - h / 2:
                k = min(int(np.searchsorted(knots, t + h / 2)), 2)
                a_x = ax[b, k] if pvx > 0 or ax[b, k] > 0 else 0.0
                px, pvx = px + pvx * h + 0.5 * a_x * h * h, max(pvx + a_x * h, 0.0)
                py, pvy = py + pvy * h + 0.5 * ay[b, k] * h * h, pvy + ay[b, k] * h
                t += h
            assert x[b, j] == pytest.approx(px, abs=1e-4) and y[b, j] == pytest.approx(py, abs=1e-4)
            assert vx[b, j] == pytest.approx(pvx, abs=1e-4) and vy[b, j] == pytest.approx(pvy, abs=1e-4)


def test_blame_rule_cases():
    """Rear-end by a vehicle behind in the ego's lane: its fault unless the ego cut in too close; a vehicle ahead:
    the ego's unless that vehicle cut in."""
    behind, in_lane = np.array([[True, True, False, False]]), np.ones((1, 4), bool)
    clean = np.array([[True, False, True, True]])
    cut_in = np.array([[False, False, False, True]])
    assert chk.blame_other(behind, in_lane, clean, cut_in).tolist() == [[True, False, False, True]]
    assert not chk.blame_other(behind, np.zeros((1, 4), bool), clean, cut_in).any()


def test_rss_safe_distance_exceeds_the_stopping_distances_gap():
    """The rear vehicle's safe distance: response at 3.5 m/s² for 2 s, then 4 m/s² to rest, less the front
    vehicle's stop at 8 m/s² (computed here by hand)."""
    v_front, v_rear = 20.0, 20.0
    v_r = v_rear + 3.5 * 2.0
    rear = v_rear * 2.0 + 0.5 * 3.5 * 4.0 + v_r**2 / 8.0
    assert float(chk.rear_safe_distance(v_front, v_rear)) == pytest.approx(rear - v_front**2 / 16.0)


# -- the shipped sample ------------------------------------------------------------------------------------------


def test_shipped_sample_no_ego_responsible_collision():
    from safelane.recorded.store import load_recording, sample_paths

    table = run_log_loop([load_recording(p) for p in sample_paths()])
    s = summary(table)
    assert s["events"] == len(table) >= 5
    assert s["collisions_ego"] == 0
    assert s["pm_ego"] == 0
    assert s["completed"] >= 1
    assert (table["human_time_s"] > 0).all()
