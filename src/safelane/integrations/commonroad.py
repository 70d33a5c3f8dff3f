"""CommonRoad out (extra ``commonroad``): any episode of ours as a CommonRoad scenario, and back.

An episode of any host — the built-in simulator, highway-env, SUMO — is first one :class:`EpisodeTrajectories`
(:mod:`.commonroad_hosts` fills it: per vehicle and 0.1 s period the centre ``x``, ``y`` [m], heading [rad], speed
[m/s], and each vehicle's length and width [m]; the lanes' centres; the host's own collision verdict).
:func:`to_commonroad` turns it into a ``commonroad.scenario.scenario.Scenario`` and a ``PlanningProblemSet``:

* every lane a straight ``Lanelet`` along ``+x`` (width ``lane_width``, ids ``1, 2, …`` from the rightmost lane,
  adjacent to one another in the same direction), long enough for every vehicle of the episode;
* **the ego a** ``DynamicObstacle`` **with the id** :data:`EGO_ID` (its rectangle and its whole executed
  trajectory as a ``TrajectoryPrediction``), every other vehicle a ``DynamicObstacle`` with the id
  ``EGO_ID + 1, +2, …`` in the record's order — so a tool that replays or checks the file sees the episode as it was
  driven; and one ``PlanningProblem`` (id :data:`PLANNING_PROBLEM_ID`): the ego's initial state and the goal of
  reaching the target lanelet within the episode, for a planner that wants to drive the episode itself (remove the
  ego obstacle first: :func:`split_ego`);
* time step ``dt`` = the episode's period (0.1 s); states are ``CustomState`` (position, orientation, velocity,
  time step).

Frame: ``x`` along the road, ``y`` to the left (CommonRoad's); the adapters map their hosts' frames into it
(highway-env's ``y`` grows to the right: mirrored). :func:`write_commonroad` writes the XML format with
``commonroad.common.writer.file_writer_xml.XMLFileWriter`` (6 decimals, i.e. µm, instead of its default 4);
:func:`read_commonroad` reads it with ``commonroad.common.reader.file_reader_xml.XMLFileReader``. Only these XML
modules are imported: ``commonroad.common.file_reader`` / ``file_writer`` import the protobuf format's generated code,
which breaks under the protobuf that onnx needs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

INSTALL_HINT = 'pip install "safelane[commonroad]"  (commonroad-io < 2026 and commonroad-drivability-checker)'
#: The ego's obstacle id; the others follow it (``EGO_ID + i`` for the record's vehicle ``i``).
EGO_ID = 100
PLANNING_PROBLEM_ID = 99
#: Decimals the XML writer keeps (truncating): 1 µm.
DECIMALS = 6
#: How far the lanelets reach beyond the first and last position of any vehicle [m].
ROAD_MARGIN_M = 50.0


def commonroad_modules():
    """Import commonroad-io's pieces this module needs (the XML reader and writer only), with the install hint."""
    try:
        from commonroad.common.reader import file_reader_xml
        from commonroad.common.util import Interval
        from commonroad.common.writer import file_writer_xml
        from commonroad.geometry import shape
        from commonroad.planning import goal, planning_problem
        from commonroad.prediction import prediction
        from commonroad.scenario import lanelet, obstacle, scenario, state, trajectory
    except ImportError as exc:
        raise ImportError(f"CommonRoad export needs commonroad-io: {INSTALL_HINT} ({exc})") from exc
    return dict(reader=file_reader_xml, writer=file_writer_xml, shape=shape, goal=goal, pp=planning_problem,
                prediction=prediction, lanelet=lanelet, obstacle=obstacle, scenario=scenario, state=state,
                trajectory=trajectory, Interval=Interval)  # fmt: skip


@dataclass(frozen=True)
class EpisodeTrajectories:
    """One episode's trajectories, whatever host drove it (vehicle ``0`` is the ego).

    ``x``, ``y`` (centres, CommonRoad's frame: ``y`` to the left), ``heading`` [rad] and ``speed`` [m/s] are
    ``(V, T)``: vehicle by period, ``t = k · dt``; ``NaN`` where a vehicle is not on the road (present periods must
    be contiguous; the ego is present throughout). ``length``, ``width``: ``(V,)`` [m]. ``lanes_y``: the lanes'
    centres; ``target_lane``: the index (into ``lanes_y``) of the lane the ego changes into. The host's verdict:
    ``collision_step`` — the first step ``k`` at which the host reports the ego's collision (the built-in
    simulator: its continuous-time check found contact in the period ``((k−1)·dt, k·dt]``; highway-env and SUMO:
    their checks of the positions at ``k·dt``), ``-1`` for none; ``collision_partner`` its partner's name where the
    host names one."""

    host: str
    episode_id: int
    dt: float
    names: tuple[str, ...]
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    lanes_y: tuple[float, ...]
    lane_width: float
    target_lane: int
    shielded: bool
    collision_step: int = -1
    collision_partner: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        arrays = {k: np.asarray(getattr(self, k), float) for k in ("x", "y", "heading", "speed", "length", "width")}
        for k, a in arrays.items():
            object.__setattr__(self, k, a)
        n_vehicles = len(self.names)
        if not self.names or self.names[0] != "ego":
            raise ValueError(f"names[0] must be 'ego'; got {self.names[:1]}")
        shape = arrays["x"].shape
        if len(shape) != 2 or shape[0] != n_vehicles or shape[1] < 1:
            raise ValueError(f"x must be (V, T) with V = len(names) = {n_vehicles}; got {shape}")
        for k in ("y", "heading", "speed"):
            if arrays[k].shape != shape:
                raise ValueError(f"{k} has shape {arrays[k].shape}; x has {shape}")
        for k in ("length", "width"):
            if arrays[k].shape != (n_vehicles,) or not (arrays[k] > 0).all():
                raise ValueError(f"{k} must be (V,) = ({n_vehicles},) and positive; got {arrays[k]}")
        present = self.present
        if not present[0].all():
            raise ValueError("the ego must be present at every step")
        # contiguous presence: a vehicle's present steps fill the span from its first to its last
        first = present.argmax(1)
        last = present.shape[1] - 1 - present[:, ::-1].argmax(1)
        gaps = np.flatnonzero(present.any(1) & (last - first + 1 != present.sum(1)))
        if gaps.size:
            raise ValueError(f"vehicle {self.names[gaps[0]]!r} leaves and comes back: present steps must be contiguous")
        if not 0 <= self.target_lane < len(self.lanes_y):
            raise ValueError(f"target_lane {self.target_lane} is not an index of lanes_y {self.lanes_y}")
        if not -1 <= self.collision_step < shape[1]:
            raise ValueError(f"collision_step {self.collision_step} outside [-1, {shape[1] - 1}]")

    @property
    def steps(self) -> int:
        return self.x.shape[1]

    @property
    def present(self) -> np.ndarray:
        """``(V, T)``: where a vehicle is on the road."""
        return np.isfinite(self.x) & np.isfinite(self.y)

    @property
    def collided(self) -> bool:
        """The host's verdict: the ego collided."""
        return self.collision_step >= 0

    def take_steps(self, n: int) -> EpisodeTrajectories:
        """The first ``n`` steps (the host's verdict kept where it falls inside them)."""
        cut = {k: getattr(self, k)[:, :n] for k in ("x", "y", "heading", "speed")}
        step = self.collision_step if self.collision_step < n else -1
        return dataclasses.replace(self, **cut, collision_step=step,
                                   collision_partner=self.collision_partner if step >= 0 else "")  # fmt: skip


def to_commonroad(episode: EpisodeTrajectories, *, planning_problem: bool = True):
    """``(scenario, planning_problem_set)`` of one episode (see the module docstring for the layout and ids)."""
    cr = commonroad_modules()
    dt = float(episode.dt)
    scenario_id = cr["scenario"].ScenarioID(country_id="ZAM", map_name=_map_name(episode.host),
                                            map_id=int(episode.episode_id) + 1)  # fmt: skip
    scenario = cr["scenario"].Scenario(dt=dt, scenario_id=scenario_id, author="safelane", affiliation="safelane",
                                       source=f"safelane {episode.host}")  # fmt: skip
    lanelets = _lanelets(cr, episode)
    scenario.add_objects(lanelets)
    for i in range(len(episode.names)):
        obstacle = _obstacle(cr, episode, i)
        if obstacle is not None:
            scenario.add_objects(obstacle)
    problems = cr["pp"].PlanningProblemSet()
    if planning_problem:
        problems.add_planning_problem(_planning_problem(cr, episode, lanelets[episode.target_lane]))
    return scenario, problems


def write_commonroad(path: Path | str, episode: EpisodeTrajectories | None = None, *, scenario=None,
                     planning_problems=None) -> Path:  # fmt: skip
    """Write one episode (or a ready ``scenario`` with its ``planning_problems``) as a CommonRoad XML file at
    ``path`` (overwritten; parent folders created). Returns ``path``."""
    cr = commonroad_modules()
    if episode is not None:
        if scenario is not None:
            raise ValueError("give either an episode or a scenario, not both")
        scenario, planning_problems = to_commonroad(episode)
    if scenario is None:
        raise ValueError("nothing to write: give an episode or a scenario")
    if planning_problems is None:
        planning_problems = cr["pp"].PlanningProblemSet()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)  # the writer prints a line when it replaces a file
    # A location given, else the writer warns that it writes the default one.
    writer = cr["writer"].XMLFileWriter(
        scenario, planning_problems, author="safelane", affiliation="safelane", source=scenario.source or "safelane",
        tags=set(), location=cr["scenario"].Location(), decimal_precision=DECIMALS,
    )
    writer.write_to_file(str(path), cr["writer"].OverwriteExistingFile.ALWAYS)
    return path


def read_commonroad(path: Path | str):
    """``(scenario, planning_problem_set)`` read back with commonroad-io's XML reader."""
    cr = commonroad_modules()
    return cr["reader"].XMLFileReader(str(path)).open()


def split_ego(scenario):
    """``(others, ego)``: the scenario's dynamic obstacles other than the ego, and the ego's obstacle
    (:data:`EGO_ID`). The scenario is not changed."""
    ego = scenario.obstacle_by_id(EGO_ID)
    if ego is None:
        raise ValueError(f"the scenario has no ego obstacle (id {EGO_ID}); was it written by safelane?")
    return [o for o in scenario.dynamic_obstacles if o.obstacle_id != EGO_ID], ego


# -- pieces ------------------------------------------------------------------------------------------------------
def _map_name(host: str) -> str:
    return "".join(ch for ch in host.title() if ch.isalnum()) or "Safelane"


def _lanelets(cr, ep: EpisodeTrajectories) -> list:
    present = ep.present
    lo = float(np.nanmin(np.where(present, ep.x, np.nan))) - ROAD_MARGIN_M
    hi = float(np.nanmax(np.where(present, ep.x, np.nan))) + ROAD_MARGIN_M
    xs = np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / 20.0)) + 1))
    order = np.argsort(ep.lanes_y)  # ids 1, 2, … from the rightmost lane (smallest y)
    ids = {int(lane): k + 1 for k, lane in enumerate(order)}
    lanelets = []
    for lane, yc in enumerate(ep.lanes_y):
        half = 0.5 * ep.lane_width
        rank = int(np.flatnonzero(order == lane)[0])
        left = ids[int(order[rank + 1])] if rank + 1 < len(order) else None
        right = ids[int(order[rank - 1])] if rank > 0 else None
        lanelets.append(cr["lanelet"].Lanelet(
            left_vertices=np.column_stack([xs, np.full_like(xs, yc + half)]),
            center_vertices=np.column_stack([xs, np.full_like(xs, yc)]),
            right_vertices=np.column_stack([xs, np.full_like(xs, yc - half)]),
            lanelet_id=ids[lane], adjacent_left=left, adjacent_left_same_direction=True if left else None,
            adjacent_right=right, adjacent_right_same_direction=True if right else None,
            lanelet_type={cr["lanelet"].LaneletType.HIGHWAY},
        ))  # fmt: skip
    return lanelets


def _state(cr, ep: EpisodeTrajectories, i: int, k: int, initial: bool = False):
    cls = cr["state"].InitialState if initial else cr["state"].CustomState
    kw = dict(position=np.array([ep.x[i, k], ep.y[i, k]]), orientation=float(ep.heading[i, k]),
              velocity=float(ep.speed[i, k]), time_step=int(k))  # fmt: skip
    if initial:
        kw.update(acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
    return cls(**kw)


def _obstacle(cr, ep: EpisodeTrajectories, i: int):
    steps = np.flatnonzero(ep.present[i])
    if steps.size == 0:
        return None
    shape = cr["shape"].Rectangle(length=float(ep.length[i]), width=float(ep.width[i]))
    first = int(steps[0])
    initial = _state(cr, ep, i, first, initial=True)
    prediction = None
    if steps.size > 1:
        states = [_state(cr, ep, i, int(k)) for k in steps[1:]]
        prediction = cr["prediction"].TrajectoryPrediction(cr["trajectory"].Trajectory(first + 1, states), shape)
    return cr["obstacle"].DynamicObstacle(EGO_ID + i, cr["obstacle"].ObstacleType.CAR, shape, initial, prediction)


def _planning_problem(cr, ep: EpisodeTrajectories, target):
    initial = _state(cr, ep, 0, 0, initial=True)
    goal_state = cr["state"].CustomState(time_step=cr["Interval"](1, max(ep.steps - 1, 1)),
                                         position=target.polygon)  # fmt: skip
    goal = cr["goal"].GoalRegion([goal_state], lanelets_of_goal_position={0: [target.lanelet_id]})
    return cr["pp"].PlanningProblem(PLANNING_PROBLEM_ID, initial, goal)
