"""Loaders of recorded traffic on tiny files the tests write: NGSIM (units, lane ids, time base, smoothing, errors)
and CommonRoad (through commonroad-io's own writer; skipped with the install hint without it)."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.errors import InputError
from safelane.recorded import NO_LANE, load_commonroad
from safelane.recorded.ngsim import COLUMNS, FEET_M, load_ngsim, sema
from safelane.recorded.store import kind_of, load_npz, load_recording, save_npz


def ngsim_rows(vehicle, frames, front_ft, lateral_ft, lane, length_ft=15.0, width_ft=6.0):
    """Rows of one vehicle in NGSIM's 18 columns (the speed/acc columns hold nonsense: the loader must not use them)."""
    rows = []
    for f, y, x, ln in zip(frames, front_ft, lateral_ft, lane, strict=True):
        rows.append([vehicle, f, len(frames), 1_118_846_980_200 + f * 100, x, y, 0, 0, length_ft, width_ft, 2,
                     -99.0, 99.0, ln, 0, 0, 0, 0])  # fmt: skip
    return rows


def write_ngsim(path, rows, header=True, columns=COLUMNS):
    lines = [",".join(columns)] if header else []
    lines += [",".join(str(v) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def two_cars(tmp_path, header=True):
    """Car 7 at 50 ft/s in lane 2 (front from 100 ft), car 9 at 30 ft/s in lane 3, frames 1000..1039."""
    frames = np.arange(1000, 1040)
    t = (frames - 1000) * 0.1
    rows = ngsim_rows(7, frames, 100 + 50 * t, np.full(40, 18.0), np.full(40, 2))
    rows += ngsim_rows(9, frames, 40 + 30 * t, np.full(40, 30.0), np.full(40, 3), length_ft=20.0)
    return write_ngsim(tmp_path / "trajectories.csv", rows, header)


def test_ngsim_units_lanes_and_time_base(tmp_path):
    rec = load_ngsim(two_cars(tmp_path))
    assert rec.dt == 0.1 and rec.t0 == pytest.approx(100.0) and rec.n_frames == 40
    assert rec.vehicle_ids.tolist() == [7, 9]
    assert rec.length == pytest.approx([15 * FEET_M, 20 * FEET_M])
    # centre = front - length/2, in metres; y = -Local_X
    assert rec.x[0, 0] == pytest.approx((100 - 7.5) * FEET_M, abs=1e-9)
    assert rec.y[1, 5] == pytest.approx(-30 * FEET_M)
    assert rec.speed[0, 20] == pytest.approx(50 * FEET_M, rel=1e-9)  # smoothing keeps a constant speed
    assert rec.accel[0, 20] == pytest.approx(0.0, abs=1e-9)
    assert rec.lane[1].tolist() == [3] * 40 and rec.valid.all()
    # lane 2 is left of lane 3: its bounds lie above (y is left-positive); they are neighbours
    two, three = rec.lanes.index([2, 3])
    assert rec.lanes.y_right[two] == pytest.approx(rec.lanes.y_left[three])
    assert rec.lanes.right[two] == 3 and rec.lanes.left[three] == 2


def test_ngsim_without_header_reads_the_official_order(tmp_path):
    a = load_ngsim(two_cars(tmp_path))
    b = load_ngsim(two_cars(tmp_path, header=False))
    assert np.array_equal(a.x, b.x) and np.array_equal(a.lane, b.lane)


@pytest.mark.parametrize("column", ["Local_Y", "Lane_ID", "Global_Time"])
def test_a_missing_column_names_the_file_and_the_column(tmp_path, column):
    rows = ngsim_rows(1, range(10), range(10), [5] * 10, [1] * 10)
    keep = [i for i, c in enumerate(COLUMNS) if c != column]
    path = write_ngsim(tmp_path / "cut.csv", [[r[i] for i in keep] for r in rows], columns=[COLUMNS[i] for i in keep])
    with pytest.raises(InputError, match=rf"cut\.csv.*missing column '{column}'"):
        load_ngsim(path)


def test_a_non_numeric_value_names_the_column_and_row(tmp_path):
    rows = ngsim_rows(1, range(10), range(10), [5] * 10, [1] * 10)
    rows[3][COLUMNS.index("Local_X")] = "abc"
    with pytest.raises(InputError, match=r"bad\.csv.*'Local_X', data row 4"):
        load_ngsim(write_ngsim(tmp_path / "bad.csv", rows))


def test_frames_not_a_tenth_of_a_second_apart_are_refused(tmp_path):
    rows = ngsim_rows(1, range(10), range(10), [5] * 10, [1] * 10)
    rows[5][COLUMNS.index("Global_Time")] += 50
    with pytest.raises(InputError, match="Global_Time"):
        load_ngsim(write_ngsim(tmp_path / "clock.csv", rows))


def test_sema_removes_noise_and_keeps_lines():
    """An independent check of the smoothing: a straight line stays (the kernel is symmetric), white noise shrinks."""
    rng = np.random.default_rng(0)
    t = np.arange(200) * 0.1
    line = 3.0 + 12.0 * t
    valid = np.ones((1, 200), bool)
    assert np.allclose(sema(line[None], valid, 0.5, 0.1), line[None], atol=1e-9)
    noisy = line + rng.normal(0, 0.3, 200)
    smooth = sema(noisy[None], valid, 0.5, 0.1)[0]
    assert np.std(smooth[20:-20] - line[20:-20]) < 0.5 * np.std(noisy - line)


def test_a_file_that_is_no_scenario_is_not_loaded(tmp_path):
    (tmp_path / "notes.txt").write_text("hello\n")
    assert kind_of(tmp_path / "notes.txt") is None
    with pytest.raises(InputError, match=r"notes\.txt"):
        load_recording(tmp_path / "notes.txt")
    with pytest.raises(InputError, match="no such file"):
        load_ngsim(tmp_path / "missing.csv")


def test_npz_round_trip_is_lossless(tmp_path):
    rec = load_ngsim(two_cars(tmp_path))
    back = load_npz(save_npz(rec, tmp_path / "r.npz"))
    for name in ("x", "y", "speed", "accel", "length"):
        assert np.array_equal(getattr(rec, name), getattr(back, name), equal_nan=True)
    for name in ("lane", "valid", "vehicle_ids"):
        assert np.array_equal(getattr(rec, name), getattr(back, name))
    assert np.array_equal(rec.lanes.y_left, back.lanes.y_left)


# -- CommonRoad -----------------------------------------------------------------------------------------------


def _commonroad():
    try:
        import commonroad.common.writer.file_writer_xml  # noqa: F401
    except ImportError:
        pytest.skip('commonroad-io is not installed: pip install "safelane[commonroad]"')


def write_two_lane_scenario(path):
    """Two straight lanes along +x (3.5 m wide, lane centres y = 0 and y = 3.5), one car changing from the right lane
    to the left (its centre crosses y = 1.75 at t = 2.0 s) and one car keeping the left lane."""
    from commonroad.common.writer.file_writer_interface import OverwriteExistingFile
    from commonroad.common.writer.file_writer_xml import XMLFileWriter
    from commonroad.geometry.shape import Rectangle
    from commonroad.planning.planning_problem import PlanningProblemSet
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.lanelet import Lanelet
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
    from commonroad.scenario.scenario import Scenario
    from commonroad.scenario.state import InitialState, KSState
    from commonroad.scenario.trajectory import Trajectory

    xs = np.linspace(0.0, 200.0, 21)

    def line(y):
        return np.stack([xs, np.full_like(xs, y)], 1)

    def lanelet(lid, y_centre, left=None, right=None):
        return Lanelet(line(y_centre + 1.75), line(y_centre), line(y_centre - 1.75), lid, adjacent_left=left,
                       adjacent_left_same_direction=True if left else None, adjacent_right=right,
                       adjacent_right_same_direction=True if right else None)  # fmt: skip

    scenario = Scenario(dt=0.1)
    scenario.add_objects([lanelet(1, 0.0, left=2), lanelet(2, 3.5, right=1)])

    def car(oid, x0, v, y_of_t):
        states = [KSState(time_step=k, position=np.array([x0 + v * 0.1 * k, y_of_t(0.1 * k)]), velocity=v,
                          orientation=0.0, steering_angle=0.0) for k in range(1, 41)]  # fmt: skip
        shape = Rectangle(4.5, 1.8)
        init = InitialState(time_step=0, position=np.array([x0, y_of_t(0.0)]), velocity=v, orientation=0.0,
                            acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)  # fmt: skip
        return DynamicObstacle(oid, ObstacleType.CAR, shape, init, TrajectoryPrediction(Trajectory(1, states), shape))

    scenario.add_objects(car(100, 20.0, 15.0, lambda t: float(np.clip((t - 1.0) * 1.75, 0.0, 3.5))))
    scenario.add_objects(car(101, 80.0, 15.0, lambda t: 3.5))
    XMLFileWriter(scenario, PlanningProblemSet(), "safelane tests", "TUM", "test", set()).write_to_file(
        str(path), OverwriteExistingFile.ALWAYS
    )
    return path


def test_commonroad_frame_lanes_and_time_base(tmp_path):
    _commonroad()
    rec = load_commonroad(write_two_lane_scenario(tmp_path / "two_lanes.xml"))
    assert rec.dt == pytest.approx(0.1) and rec.n_frames == 41 and rec.n_vehicles == 2
    assert rec.lanes.ids.tolist() == [1, 2]  # 1 = leftmost
    assert rec.lanes.left.tolist() == [NO_LANE, 1] and rec.lanes.right.tolist() == [2, NO_LANE]
    # the reference line is a lane's centreline along +x: x is the arc length from its start, y left-positive
    assert rec.x[0, 0] == pytest.approx(20.0, abs=1e-6) and rec.x[0, 40] == pytest.approx(80.0, abs=1e-6)
    assert rec.lanes.line_between(2, 1) - rec.y[1, 0] == pytest.approx(-1.75, abs=1e-6)
    lanes = rec.lane[0]
    assert lanes[0] == 2 and lanes[-1] == 1
    assert np.flatnonzero(np.diff(lanes))[0] + 1 == 20  # y = 1.75 reached at t = 2.0 s: frame 20
    assert rec.length == pytest.approx([4.5, 4.5]) and rec.speed[0, 10] == pytest.approx(15.0)


def test_a_file_that_is_not_commonroad_names_the_file(tmp_path):
    _commonroad()
    bad = tmp_path / "broken.xml"
    bad.write_text("<commonRoad><lanelet id='1'><leftBound></commonRoad>")
    with pytest.raises(InputError, match=r"broken\.xml"):
        load_commonroad(bad)
