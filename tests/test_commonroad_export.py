"""CommonRoad out and the drivability checker as referee (safelane.integrations.commonroad*): hand-built episodes with
a known collision step and near misses, the file's round trip, and the simulator's episodes refereed.

The referee's judge is commonroad_dc (C++, no safelane code); the expected steps below are computed by hand.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from safelane.integrations.commonroad import INSTALL_HINT, EpisodeTrajectories

pytest.importorskip("commonroad", reason=f"commonroad-io is not installed: {INSTALL_HINT}")
pytest.importorskip("commonroad_dc", reason=f"the drivability checker is not installed: {INSTALL_HINT}")

from safelane.integrations.commonroad import (
    EGO_ID,
    PLANNING_PROBLEM_ID,
    commonroad_modules,
    read_commonroad,
    split_ego,
    to_commonroad,
    write_commonroad,
)
from safelane.integrations.commonroad_referee import (
    compare,
    drivability_collisions,
    interpolated_contact,
    referee_episode,
)

DT = 0.1
LENGTH, WIDTH, LANE = 5.0, 2.0, 3.5


def two_vehicles(ego_xy, other_xy, *, other_heading=0.0, collision_step=-1, steps=40, host="simulator"):
    """An episode of the ego and one other vehicle ``L1`` (5 × 2 m each) with the given centre tracks
    (callables of the step ``k``)."""
    k = np.arange(steps)
    ex, ey = (np.broadcast_to(np.asarray(f(k), float), (steps,)) for f in ego_xy)
    ox, oy = (np.broadcast_to(np.asarray(f(k), float), (steps,)) for f in other_xy)
    return EpisodeTrajectories(
        host=host, episode_id=7, dt=DT, names=("ego", "L1"), x=np.stack([ex, ox]), y=np.stack([ey, oy]),
        heading=np.stack([np.zeros(steps), np.full(steps, other_heading)]), speed=np.full((2, steps), 20.0),
        length=[LENGTH, LENGTH], width=[WIDTH, WIDTH], lanes_y=(0.0, LANE), lane_width=LANE, target_lane=1,
        shielded=False, collision_step=collision_step,
    )  # fmt: skip


def rear_end_at_step_26():
    """The ego at 20 m/s behind a vehicle at 10 m/s in its own lane, 30.3 m ahead (centres): contact (gap 5 m) at
    t = 2.53 s, so the first sample with overlap is step 26 (gap 4.3 m; step 25: 5.3 m)."""
    return two_vehicles((lambda k: 20.0 * k * DT, lambda k: 0.0), (lambda k: 30.3 + 10.0 * k * DT, lambda k: 0.0),
                        collision_step=26)  # fmt: skip


def beside(lateral_m: float, *, other_heading=0.0):
    """Another vehicle driving beside the ego at the same speed, ``lateral_m`` apart (centres)."""
    return two_vehicles((lambda k: 20.0 * k * DT, lambda k: 0.0), (lambda k: 20.0 * k * DT, lambda k: lateral_m),
                        other_heading=other_heading)  # fmt: skip


def behind_at(gap_m: float):
    """Another vehicle ahead in the ego's lane at the same speed, ``gap_m`` apart (centres)."""
    return two_vehicles((lambda k: 20.0 * k * DT, lambda k: 0.0), (lambda k: gap_m + 20.0 * k * DT, lambda k: 0.0))


# -- the referee on hand-built episodes ------------------------------------------------------------------------
def test_known_collision_is_found_at_its_step():
    ep = rear_end_at_step_26()
    verdict, agreement = referee_episode(ep)
    assert verdict.collision and verdict.first_step == 26
    assert verdict.partners == (EGO_ID + 1,)
    assert verdict.steps == tuple(range(26, 36))  # |dx| = |30.3 − k| < 5 m: they pass through each other
    assert agreement.kind == "both collide" and agreement.agree


@pytest.mark.parametrize(("gap", "collides"), [(5.04, False), (4.96, True)])
def test_longitudinal_near_miss_by_4_cm(gap, collides):
    verdict = referee_episode(behind_at(gap))[0]
    assert verdict.collision is collides
    assert verdict.first_step == (0 if collides else -1)


@pytest.mark.parametrize(("lateral", "collides"), [(2.03, False), (1.97, True), (-2.03, False), (-1.97, True)])
def test_lateral_near_miss_by_3_cm(lateral, collides):
    """Width, not length, across the road: a swapped rectangle would collide at 2.03 m."""
    assert referee_episode(beside(lateral))[0].collision is collides


def test_heading_turns_the_rectangle():
    """2.4 m beside the ego (centres): clear when aligned (1 + 1 m half widths), hit when turned by 90° (the other's
    half length 2.5 m across the road). Headings are radians."""
    assert not referee_episode(beside(2.4))[0].collision
    assert referee_episode(beside(2.4, other_heading=np.pi / 2))[0].collision


def test_host_verdict_disagreements_are_named():
    ep = rear_end_at_step_26()
    clear = EpisodeTrajectories(**{**ep.__dict__, "collision_step": -1})
    verdict = drivability_collisions(to_commonroad(clear)[0])
    agreement = compare(clear, verdict)
    assert agreement.kind == "checker only" and not agreement.agree and "step 26" in agreement.reason
    late = EpisodeTrajectories(**{**ep.__dict__, "collision_step": 30, "host": "sumo"})
    assert not compare(late, verdict).agree  # a sampled host must find the same first step
    near = behind_at(5.04)
    claimed = EpisodeTrajectories(**{**near.__dict__, "collision_step": 5})
    result = compare(claimed, drivability_collisions(to_commonroad(claimed)[0]))
    assert result.kind == "host only" and not result.agree and "unexplained" in result.reason


def test_contact_between_samples_is_recognised_for_the_continuous_host():
    """A corner graze: at step 10 the ego overlaps L1's lane laterally (centres 1.5 m apart) but is 5.2 m behind
    it, at step 11 it is 4.6 m behind but 2.1 m apart laterally (it swerved back); in between (a straight
    relative motion) both gaps are closed at once, for fractions 1/3 < f < 5/6 of the period. The simulator's
    continuous check would say step 11; the sampled checker sees no overlap; on the period interpolated at 0.001 s
    it finds the first contact at f = 0.34 (t = 1.034 s)."""
    ep = two_vehicles((lambda k: 20.0 * k * DT, lambda k: np.where(k <= 10, 2.0, 1.4)),
                      (lambda k: 20.0 * k * DT + 5.2 - 0.6 * (k - 10), lambda k: LANE), collision_step=11)  # fmt: skip
    verdict = drivability_collisions(to_commonroad(ep)[0])
    assert not verdict.collision
    agreement = compare(ep, verdict)
    assert agreement.kind == "both collide" and agreement.agree
    assert "between samples" in agreement.reason and "t = 1.034 s" in agreement.reason
    assert interpolated_contact(ep, 10) is None and interpolated_contact(ep, 12) is None
    sampled = EpisodeTrajectories(**{**ep.__dict__, "host": "sumo"})  # a sampled host has no such excuse
    assert compare(sampled, verdict).kind == "host only" and not compare(sampled, verdict).agree


def test_ego_as_trajectory_with_shape_gives_the_same_verdict():
    scenario, _ = to_commonroad(rear_end_at_step_26())
    others, ego = split_ego(scenario)
    assert [o.obstacle_id for o in others] == [EGO_ID + 1]
    by_obstacle = drivability_collisions(scenario, ego)
    cr = commonroad_modules()
    first = ego.initial_state
    start = cr["state"].CustomState(position=first.position, orientation=first.orientation, velocity=first.velocity,
                                    time_step=0)  # fmt: skip
    trajectory = cr["trajectory"].Trajectory(0, [start, *ego.prediction.trajectory.state_list])
    assert drivability_collisions(scenario, trajectory, ego_shape=ego.obstacle_shape) == by_obstacle


# -- the file ------------------------------------------------------------------------------------------------------
def test_round_trip_through_the_xml_file(tmp_path):
    ep = two_vehicles((lambda k: 1.234567 + 29.5 * k * DT, lambda k: 0.05 * k),
                      (lambda k: -20.0 + 30.0 * k * DT, lambda k: LANE), other_heading=0.0125)  # fmt: skip
    path = write_commonroad(tmp_path / "sub" / "episode.xml", ep)
    assert path.is_file()
    scenario, problems = read_commonroad(path)
    assert scenario.dt == pytest.approx(DT)
    lanelets = sorted(scenario.lanelet_network.lanelets, key=lambda la: la.lanelet_id)
    assert [la.lanelet_id for la in lanelets] == [1, 2]
    assert lanelets[0].adj_left == 2 and lanelets[1].adj_right == 1
    for la, yc in zip(lanelets, (0.0, LANE), strict=True):
        np.testing.assert_allclose(la.center_vertices[:, 1], yc)
        np.testing.assert_allclose(la.left_vertices[:, 1] - la.right_vertices[:, 1], LANE)
    assert lanelets[0].center_vertices[0, 0] <= min(ep.x.min(), 0) - 10
    assert lanelets[0].center_vertices[-1, 0] >= ep.x.max() + 10
    for i in range(2):
        ob = scenario.obstacle_by_id(EGO_ID + i)
        assert ob.obstacle_shape.length == LENGTH and ob.obstacle_shape.width == WIDTH
        states = [ob.initial_state, *ob.prediction.trajectory.state_list]
        assert [s.time_step for s in states] == list(range(ep.steps))
        np.testing.assert_allclose([s.position for s in states], np.column_stack([ep.x[i], ep.y[i]]), atol=1e-6)
        np.testing.assert_allclose([s.orientation for s in states], ep.heading[i], atol=1e-6)
        np.testing.assert_allclose([s.velocity for s in states], ep.speed[i], atol=1e-6)
    problem = problems.planning_problem_dict[PLANNING_PROBLEM_ID]
    np.testing.assert_allclose(problem.initial_state.position, [ep.x[0, 0], ep.y[0, 0]], atol=1e-6)
    assert problem.goal.lanelets_of_goal_position == {0: [2]}
    path.write_text(path.read_text())  # rewriting over an existing file is silent and works
    assert write_commonroad(path, ep) == path


def test_the_file_gives_the_same_verdict(tmp_path):
    for ep in (rear_end_at_step_26(), behind_at(5.04), beside(1.97)):
        from_memory = drivability_collisions(to_commonroad(ep)[0])
        from_file = drivability_collisions(read_commonroad(write_commonroad(tmp_path / "e.xml", ep))[0])
        assert from_file == from_memory


def test_vehicles_absent_for_part_of_the_episode(tmp_path):
    ep = rear_end_at_step_26()
    x = ep.x.copy()
    x[1, :5] = np.nan  # L1 appears at step 5
    late = EpisodeTrajectories(**{**ep.__dict__, "x": x})
    scenario = read_commonroad(write_commonroad(tmp_path / "late.xml", late))[0]
    assert scenario.obstacle_by_id(EGO_ID + 1).initial_state.time_step == 5
    assert drivability_collisions(scenario).first_step == 26


def test_bad_records_are_refused():
    ep = rear_end_at_step_26()
    with pytest.raises(ValueError, match="names\\[0\\] must be 'ego'"):
        EpisodeTrajectories(**{**ep.__dict__, "names": ("L1", "ego")})
    with pytest.raises(ValueError, match="y has shape"):
        EpisodeTrajectories(**{**ep.__dict__, "y": ep.y[:, :-1]})
    gappy = ep.x.copy()
    gappy[1, 10] = np.nan
    with pytest.raises(ValueError, match="contiguous"):
        EpisodeTrajectories(**{**ep.__dict__, "x": gappy})
    ego_missing = ep.x.copy()
    ego_missing[0, 3] = np.nan
    with pytest.raises(ValueError, match="ego must be present"):
        EpisodeTrajectories(**{**ep.__dict__, "x": ego_missing})
    with pytest.raises(ValueError, match="collision_step"):
        EpisodeTrajectories(**{**ep.__dict__, "collision_step": 40})


def test_import_is_lazy_and_hints_the_extra(monkeypatch):
    code = (
        "import sys; import safelane.integrations.commonroad, safelane.integrations.commonroad_referee, "
        "safelane.integrations.commonroad_hosts; "
        "print(sorted(m for m in sys.modules if m.startswith(('commonroad', 'highway_env', 'libsumo'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    monkeypatch.setitem(sys.modules, "commonroad.common.reader", None)
    with pytest.raises(ImportError, match=r"safelane\[commonroad\]"):
        commonroad_modules()
