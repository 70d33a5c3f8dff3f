"""Episodes of every host as :class:`~.commonroad.EpisodeTrajectories` (for CommonRoad out and the referee).

Each adapter records what its host drives, as the host drives it, every 0.1 s period, and the host's own verdict on
the ego's collision — none of them changes the host:

* :func:`simulator_episodes` — the built-in simulator: runs a :class:`~safelane.sim.ScenarioBatch` period by period
  through :class:`safelane.sim.step.ClosedLoop` (what ``simulate_batch`` runs) and keeps every vehicle's state; the
  verdict is the results table's ``collision`` (continuous in time), its step the period in which it first turned
  true. Bodies are the simulator's: ``vehicle_length × vehicle_width`` boxes aligned with the road (heading 0; the
  ego's lateral motion does not turn it), the original lane at ``y = 0`` and the target lane at ``y = lane_width``;
* :func:`highway_episode` — highway-env through :class:`~.highway.SafeLaneShield`: every vehicle of
  ``road.vehicles`` (centre, heading, speed, ``LENGTH``, ``WIDTH``) after the reset and after each step; highway-env's
  ``y`` grows to the right, so ``y`` and headings are mirrored into CommonRoad's frame; the verdict is
  ``info["crashed"]``. highway-env also flags a crash one step after it *predicts* contact within the next step (the
  polygons moved on at constant velocity intersect): it then pushes the pair apart by the penetration vector (its
  collision response) and sets ``crashed``; those steps are kept in ``meta["predicted_contact"]``, and the pushes in
  ``meta["impacts"]`` (step → ``[(vehicle, dx, dy)]``, in the positions of that step);
* :func:`sumo_episodes` — SUMO through :class:`~.sumo.SumoRunner` on a :class:`RecordingSumoWorld` (SUMO's own
  positions: front bumpers turned into centres along SUMO's angle); the verdict is the first entry of SUMO's
  collision list with the ego.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from .commonroad import EpisodeTrajectories


# -- the built-in simulator ---------------------------------------------------------------------------------------
def simulator_episodes(batch, *, seed: int = 0, params: Params | None = None, config=None, nominal=None,
                       traffic=None, shielded: bool | None = None):  # fmt: skip
    """``(episodes, table)``: every scenario of ``batch`` run in the built-in simulator, as the records of
    :class:`EpisodeTrajectories` (``host="simulator"``) and the simulator's own results table
    (``safelane.sim.results.results_table``; ``collision`` there is each record's verdict). Arguments as for
    :func:`safelane.sim.simulate_batch`; ``shielded`` labels the records (default: ``config.shield.enabled``)."""
    from ..planners.base import ExpertPlanner
    from ..sim import SimConfig
    from ..sim.inputs import check_settings
    from ..sim.results import results_table
    from ..sim.scenario import check_batch
    from ..sim.step import ClosedLoop

    prm, cfg = params or Params(), config or SimConfig()
    check_batch(batch, prm)
    check_settings(prm, cfg)
    sim = ClosedLoop(batch, seed, prm, cfg, nominal or ExpertPlanner(), traffic)
    b = sim.b  # with L0 where the config puts one
    state = sim.initial_state()
    frames = [_sim_frame(state)]
    first = np.full(len(b), -1)
    for k in range(1, round(cfg.horizon_s / prm.dt) + 1):
        state, _, _ = sim.step(state)
        frames.append(_sim_frame(state))
        first = np.where((first < 0) & state.collided, k, first)
    table = results_table(b, sim.finish(state))
    shielded = cfg.shield.enabled if shielded is None else shielded
    episodes = [_sim_episode(b, frames, row, int(first[row]), prm, shielded) for row in range(len(b))]
    return episodes, table


def _sim_frame(s) -> tuple:
    ex, ey, evx, evy = s.ego
    l0 = (None, None) if s.l0 is None else s.l0
    return ex.copy(), ey.copy(), np.hypot(evx, evy), s.x.copy(), s.v.copy(), l0[0], l0[1]


def _sim_episode(b, frames, row: int, first: int, prm: Params, shielded: bool) -> EpisodeTrajectories:
    slots = np.flatnonzero(b.valid[row])
    n_lead = int(b.n_connected[row]) + 1
    names = ["ego", *("F" if i == 0 else f"L{i}" for i in slots if i <= n_lead)]
    slots = slots[slots <= n_lead]
    x = [np.array([f[0][row] for f in frames])]
    y = [np.array([f[1][row] for f in frames])]
    speed = [np.array([f[2][row] for f in frames])]
    for i in slots:
        x.append(np.array([f[3][row, i] for f in frames]))
        y.append(np.full(len(frames), prm.lane_width))
        speed.append(np.array([f[4][row, i] for f in frames]))
    own = [] if frames[0][5] is None else np.flatnonzero(np.isfinite(frames[0][5][row]))
    for j in own:  # the own lane: L0, then the vehicles ahead of it (L0+1, ...)
        names.append("L0" if j == 0 else f"L0+{j}")
        x.append(np.array([f[5][row, j] for f in frames]))
        y.append(np.zeros(len(frames)))
        speed.append(np.array([f[6][row, j] for f in frames]))
    n = len(names)
    return EpisodeTrajectories(
        host="simulator", episode_id=int(b.scenario_id[row]), dt=prm.dt, names=tuple(names), x=np.stack(x),
        y=np.stack(y), heading=np.zeros((n, len(frames))), speed=np.stack(speed),
        length=np.full(n, prm.vehicle_length), width=np.full(n, prm.vehicle_width), lanes_y=(0.0, prm.lane_width),
        lane_width=prm.lane_width, target_lane=1, shielded=shielded, collision_step=first,
    )  # fmt: skip


# -- highway-env ----------------------------------------------------------------------------------------------------
def highway_episode(env, policy, seed: int, *, episode_id: int | None = None) -> EpisodeTrajectories:
    """One episode of a :class:`~.highway.SafeLaneShield` env from ``reset(seed=seed)`` until it terminates or is
    truncated, ``policy(env) -> (a_x, a_y)`` acting each step. Vehicles are named by the scene's roles (``F``,
    ``L1``, …, ``L0``) where the env has them, else ``v<i>`` by their order on the road at the reset."""
    env.reset(seed=int(seed))
    u = env.unwrapped
    road = u.road
    roles = getattr(u, "scene", {}).get("roles", {})
    vehicles = list(road.vehicles)
    names = ["ego" if v is env.ego else roles.get(id(v), f"v{i}") for i, v in enumerate(vehicles)]
    order = [vehicles.index(env.ego)] + [i for i, v in enumerate(vehicles) if v is not env.ego]
    vehicles, names = [vehicles[i] for i in order], [names[i] for i in order]
    rows = [_highway_frame(road, vehicles)]
    crashed, partner, done, predicted, impacts = -1, "", False, [], {}
    while not done:
        _, _, terminated, truncated, info = env.step(policy(env))
        rows.append(_highway_frame(road, vehicles))
        if env.ego.impact is not None:  # contact predicted within the next step: pushed apart and flagged then
            predicted.append(len(rows) - 1)
        pushes = [(i, float(v.impact[0]), -float(v.impact[1])) for i, v in enumerate(vehicles)
                  if getattr(v, "impact", None) is not None]  # fmt: skip
        if pushes:  # applied in the next step (mirrored y)
            impacts[len(rows)] = pushes
        if info["crashed"] and crashed < 0:
            crashed, partner = len(rows) - 1, str(info.get("crash", {}).get("partner", ""))
        done = terminated or truncated
    data = np.array(rows)  # (T, V, 4): x, y, heading, speed in highway-env's frame
    lanes = road.network.graph[env.original_lane[0]][env.original_lane[1]]
    lanes_y = tuple(-float(lane.position(0.0, 0.0)[1]) for lane in lanes)  # mirrored: y to the left
    return EpisodeTrajectories(
        host="highway-env", episode_id=int(seed if episode_id is None else episode_id), dt=env.params.dt,
        names=tuple(names), x=data[:, :, 0].T, y=-data[:, :, 1].T, heading=-data[:, :, 2].T, speed=data[:, :, 3].T,
        length=[float(v.LENGTH) for v in vehicles], width=[float(v.WIDTH) for v in vehicles], lanes_y=lanes_y,
        lane_width=float(lanes[0].width_at(0.0)), target_lane=int(env.target_lane[2]), shielded=bool(env.shield_on),
        collision_step=crashed, collision_partner=partner,
        meta={"seed": int(seed), "predicted_contact": predicted, "impacts": impacts},
    )  # fmt: skip


def _highway_frame(road, vehicles) -> list:
    on_road = {id(v) for v in road.vehicles}
    nan = [np.nan] * 4
    return [[float(v.position[0]), float(v.position[1]), float(v.heading), float(v.speed)] if id(v) in on_road
            else nan for v in vehicles]  # fmt: skip


# -- SUMO ------------------------------------------------------------------------------------------------------------
def recording_world_class():
    """:class:`RecordingSumoWorld` (defined on first use: it subclasses :class:`~.sumo_world.SumoWorld`, whose module
    imports nothing of SUMO until a world opens)."""
    global RecordingSumoWorld
    if RecordingSumoWorld is None:
        from .sumo_world import SumoWorld

        class _Recording(SumoWorld):
            """A :class:`~.sumo_world.SumoWorld` that records every vehicle (SUMO's own positions, angles and speeds)
            after each load and step: ``frames`` (one dict per step: id → ``(x_centre, y_centre, heading, speed)``),
            reset by each :meth:`load`."""

            frames: list

            def load(self, vehicles, sumo_controlled=frozenset()) -> None:
                super().load(vehicles, sumo_controlled)
                self.frames = [self._frame()]

            def step(self) -> None:
                super().step()
                self.frames.append(self._frame())

            def _frame(self) -> dict:
                veh, half = self.api.vehicle, 0.5 * self.params.vehicle_length
                out = {}
                for vid in veh.getIDList():
                    fx, fy = veh.getPosition(vid)
                    heading = np.radians(90.0 - veh.getAngle(vid))  # SUMO: degrees clockwise from north
                    out[vid] = (fx - half * np.cos(heading), fy - half * np.sin(heading), heading, veh.getSpeed(vid))
                return out

        RecordingSumoWorld = _Recording
    return RecordingSumoWorld


RecordingSumoWorld = None


def sumo_episodes(runner, scenarios, *, shielded: bool = True) -> list[EpisodeTrajectories]:
    """Run ``scenarios`` (:class:`~.sumo_episode.SumoScenario`) with ``runner``, a :class:`~.sumo.SumoRunner` made
    with ``world=recording_world_class()(params)``, and record each episode."""
    world = runner.world
    if not hasattr(type(world), "_frame"):
        raise TypeError("the runner's world must be a RecordingSumoWorld: SumoRunner(..., "
                        "world=recording_world_class()(params))")  # fmt: skip
    prm = runner.params
    lane_width = float(world.api.lane.getWidth("road_0")) if world.started else None
    out = []
    for sc in scenarios:
        res = runner.run(sc, shielded=shielded)
        if lane_width is None:
            lane_width = float(world.api.lane.getWidth("road_0"))
        out.append(_sumo_episode(world.frames, res, prm, world.lane_y, lane_width))
    return out


def _sumo_episode(frames, res, prm: Params, lanes_y, lane_width: float) -> EpisodeTrajectories:
    ids = ["ego", *sorted({vid for f in frames for vid in f} - {"ego"})]
    data = np.full((len(ids), len(frames), 4), np.nan)
    for k, f in enumerate(frames):
        for i, vid in enumerate(ids):
            if vid in f:
                data[i, k] = f[vid]
    ego_hits = [c for c in res.collisions if "ego" in (c.get("collider"), c.get("victim"))]
    step, partner = -1, ""
    if ego_hits:
        step = round(ego_hits[0]["t"] / prm.dt)
        partner = ego_hits[0]["victim"] if ego_hits[0]["collider"] == "ego" else ego_hits[0]["collider"]
    n = len(ids)
    return EpisodeTrajectories(
        host="sumo", episode_id=res.scenario_id, dt=prm.dt, names=tuple(ids), x=data[:, :, 0], y=data[:, :, 1],
        heading=data[:, :, 2], speed=data[:, :, 3], length=np.full(n, prm.vehicle_length),
        width=np.full(n, prm.vehicle_width), lanes_y=tuple(float(y) for y in lanes_y), lane_width=lane_width,
        target_lane=1, shielded=res.shielded, collision_step=step, collision_partner=partner,
        meta={"sumo_collisions": len(res.collisions)},
    )  # fmt: skip
