"""The CommonRoad drivability checker as an independent collision referee (extra ``commonroad``).

:func:`drivability_collisions` asks ``commonroad_dc`` — the C++ collision checker behind CommonRoad's benchmarks,
which shares no code with safelane — whether the ego's trajectory in a CommonRoad scenario touches any other
obstacle. The checker works on **time steps**: it compares each obstacle's occupancy at step ``k`` with the ego's at
step ``k`` (the rectangles at ``t = k·dt``); a contact that opens and closes between two steps is not seen.
:func:`compare` sets its verdict beside the host's own (:attr:`EpisodeTrajectories.collision_step`):

* **highway-env, SUMO**: their checks look at the positions at the end of each step too, so the two first colliding
  steps must be equal;
* **the built-in simulator**: its check is continuous in time: ``collision_step = k`` says contact began in
  ``((k−1)·dt, k·dt]``. A contact still there at ``k·dt`` is the checker's step ``k``; a contact over before it is
  a graze between samples, which the sampled checker cannot see. For those the referee looks closer: the checker
  again on the record's trajectories interpolated linearly at ``dt / 100`` over that period
  (:func:`interpolated_contact`).

* **highway-env** flags a crash also one step after its look-ahead predicted contact, having pushed the pair apart
  (its collision response; :mod:`.commonroad_hosts`), so the samples of such a crash show no overlap: the referee
  takes the recorded push out and looks at that period as above.

Agreement (:func:`compare`): both collide with the same first step (the simulator, or highway-env after a push:
or the interpolated check finds the contact in the period ``k``), or neither collides. Everything else is a
disagreement, with the reason the evidence supports.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .commonroad import EGO_ID, INSTALL_HINT, EpisodeTrajectories, commonroad_modules

#: Sub-steps per period of :func:`interpolated_contact` (0.001 s: a corner graze of a few ms between two samples,
#: as the simulator's continuous check finds them, needs them).
INTERPOLATION = 100
#: Hosts whose own check samples the positions at the steps (the others' is continuous in time: the simulator).
SAMPLED_HOSTS = ("highway-env", "sumo")


def _dc():
    try:
        from commonroad_dc import pycrcc
        from commonroad_dc.collision.collision_detection import pycrcc_collision_dispatch as dispatch
        from commonroad_dc.collision.trajectory_queries import trajectory_queries as queries
    except ImportError as exc:
        raise ImportError(f"the referee needs the CommonRoad drivability checker: {INSTALL_HINT} ({exc})") from exc
    return pycrcc, dispatch, queries


@dataclass(frozen=True)
class RefereeVerdict:
    """The drivability checker's answer for one ego trajectory.

    ``collision``: the checker (``create_collision_checker``'s ``collide``) finds the ego's time-variant object
    touching another obstacle's at some step; ``first_step``: the first such step (``-1``: none; the batch query
    ``trajectories_collision_dynamic_obstacles``); ``partners``: the obstacle ids touching the ego at
    ``first_step``; ``steps``: every colliding step."""

    collision: bool
    first_step: int
    partners: tuple[int, ...]
    steps: tuple[int, ...]


def drivability_collisions(scenario, ego_trajectory=None, *, ego_shape=None) -> RefereeVerdict:
    """The drivability checker's verdict on the ego in ``scenario``.

    ``ego_trajectory``: the ego's ``DynamicObstacle`` (default: the scenario's obstacle :data:`EGO_ID`), or a
    ``commonroad.scenario.trajectory.Trajectory`` with ``ego_shape`` (a ``Rectangle``). Every other dynamic obstacle
    of ``scenario`` is checked against it (the ego's own obstacle is left out where the scenario holds it).
    """
    pycrcc, dispatch, queries = _dc()
    cr = commonroad_modules()
    ego_states, shape, ego_id = _ego_states(scenario, ego_trajectory, ego_shape)
    others = [o for o in scenario.dynamic_obstacles if o.obstacle_id not in (ego_id, EGO_ID)]
    # The checker of the scenario without the ego (create_collision_checker converts a Scenario).
    rest = cr["scenario"].Scenario(dt=scenario.dt)
    if others:
        rest.add_objects(others)
    checker = dispatch.create_collision_checker(rest)
    ego_tvo = pycrcc.TimeVariantCollisionObject(int(ego_states[0].time_step))
    for s in ego_states:
        ego_tvo.append_obstacle(dispatch.create_collision_object(shape.rotate_translate_local(s.position,
                                                                                              s.orientation)))
    collision = bool(checker.collide(ego_tvo))
    obstacle_tvos = [dispatch.create_collision_object(o) for o in others]
    first = int(queries.trajectories_collision_dynamic_obstacles([ego_tvo], obstacle_tvos, method="fcl")[0])
    if collision != (first >= 0):
        raise RuntimeError(f"the checker's collide ({collision}) and its first-step query ({first}) disagree")
    steps, partners = _per_step(ego_tvo, obstacle_tvos, [o.obstacle_id for o in others], first)
    return RefereeVerdict(collision, first, partners, steps)


def _ego_states(scenario, ego_trajectory, ego_shape):
    """The ego's states from step to step (initial state first), its shape and its obstacle id (``None``)."""
    if ego_trajectory is None:
        ego_trajectory = scenario.obstacle_by_id(EGO_ID)
        if ego_trajectory is None:
            raise ValueError(f"no ego trajectory given and the scenario has no obstacle {EGO_ID} (the ego)")
    if hasattr(ego_trajectory, "obstacle_shape"):  # a DynamicObstacle
        states = [ego_trajectory.initial_state]
        if ego_trajectory.prediction is not None:
            states += list(ego_trajectory.prediction.trajectory.state_list)
        return states, ego_trajectory.obstacle_shape, ego_trajectory.obstacle_id
    if ego_shape is None:
        raise ValueError("a Trajectory needs ego_shape (the ego's Rectangle)")
    return list(ego_trajectory.state_list), ego_shape, None


def _per_step(ego_tvo, obstacle_tvos, ids, first: int):
    """Every colliding step of the ego and the partners at ``first`` (pairwise, step by step)."""
    steps, partners = set(), []
    for tvo, oid in zip(obstacle_tvos, ids, strict=True):
        lo = max(tvo.time_start_idx(), ego_tvo.time_start_idx())
        hi = min(tvo.time_end_idx(), ego_tvo.time_end_idx())
        for k in range(lo, hi + 1):
            if tvo.obstacle_at_time(k).collide(ego_tvo.obstacle_at_time(k)):
                steps.add(k)
                if k == first:
                    partners.append(int(oid))
    return tuple(sorted(steps)), tuple(sorted(partners))


# -- agreement with the host ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Agreement:
    """One episode's two verdicts side by side. ``kind``: ``"both collide"``, ``"both clear"``, ``"host only"``
    (the host reports a collision, the checker none) or ``"checker only"``; ``agree``: the verdicts agree (and, where
    both collide, the first steps, see the module docstring); ``reason``: why they differ, from the evidence."""

    kind: str
    agree: bool
    host_step: int
    checker_step: int
    reason: str = ""


def compare(episode: EpisodeTrajectories, verdict: RefereeVerdict) -> Agreement:
    """The referee's verdict against the host's own (module docstring: how the steps are compared)."""
    host, checker = episode.collision_step, verdict.first_step
    sampled = episode.host in SAMPLED_HOSTS
    if host < 0 and checker < 0:
        return Agreement("both clear", True, host, checker)
    # A continuous host's contact that the samples miss: the checker on the interpolated period (module docstring).
    between = None if sampled or host < 0 or checker == host else interpolated_contact(episode, host)
    if between is not None:
        return Agreement("both collide", True, host, checker, f"the first contact fell between samples {between}")
    if host >= 0 and checker >= 0:
        agree = checker == host
        reason = "" if agree else f"first steps differ by {checker - host}"
        return Agreement("both collide", agree, host, checker, reason)
    if host >= 0:
        if host - 1 in episode.meta.get("predicted_contact", ()):
            t = interpolated_contact(unpushed(episode, host), host)
            why = (f"highway-env's predicted contact: at step {host - 1} its look-ahead over the next step (constant "
                   "velocity) intersected, its collision response pushed the pair apart and flagged the crash, so "
                   "no overlap at the samples; ")  # fmt: skip
            if t is not None:  # the contact is real: the push hid it from the samples
                return Agreement("both collide", True, host, checker, why + f"without the push: contact {t}")
            return Agreement("host only", False, host, checker, why + (
                "without the push the checker finds no contact inside the period either (interpolated at "
                f"{episode.dt / INTERPOLATION:g} s): the look-ahead, each separating axis widened by the step's "
                "displacement, over-approximates"))  # fmt: skip
        return Agreement("host only", False, host, checker, _unexplained(episode, host))
    return Agreement("checker only", False, host, checker, _checker_only_reason(episode, verdict))


def unpushed(episode: EpisodeTrajectories, k: int) -> EpisodeTrajectories:
    """The record with highway-env's collision response of step ``k`` taken out (``meta["impacts"]``)."""
    pushes = episode.meta.get("impacts", {}).get(k, [])
    if not pushes:
        return episode
    x, y = episode.x.copy(), episode.y.copy()
    for i, dx, dy in pushes:
        x[i, k] -= dx
        y[i, k] -= dy
    return dataclasses.replace(episode, x=x, y=y)


def interpolated_contact(episode: EpisodeTrajectories, k: int, factor: int | None = None) -> str | None:
    """Evidence for a contact inside the period ``((k−1)·dt, k·dt]`` that the samples do not show: the checker on
    the record's positions and headings interpolated linearly at ``dt / factor`` (default :data:`INTERPOLATION`)
    over that period (a host's motion inside a period is not linear: constant accelerations up to ``a`` depart from
    the chord by up to ``a·dt²/8``, 1 cm at 8 m/s²). Returns where it finds contact, as words, or ``None``."""
    factor = INTERPOLATION if factor is None else factor
    if k < 1:
        return None
    from .commonroad import to_commonroad

    w = np.linspace(0.0, 1.0, factor + 1)

    def fine(a):
        return a[:, k - 1 : k] * (1.0 - w) + a[:, k : k + 1] * w

    sub = dataclasses.replace(episode, dt=episode.dt / factor, x=fine(episode.x), y=fine(episode.y),
                              heading=fine(episode.heading), speed=fine(episode.speed), collision_step=-1,
                              collision_partner="", meta={})  # fmt: skip
    present = sub.present
    if not present[0].all():
        return None
    keep = [i for i in range(len(sub.names)) if present[i].all() or i == 0]
    if len(keep) < 2:
        return None
    sub = dataclasses.replace(sub, names=tuple(sub.names[i] for i in keep), length=sub.length[keep],
                              width=sub.width[keep], **{f: getattr(sub, f)[keep] for f in ("x", "y", "heading",
                                                                                         "speed")})  # fmt: skip
    first = drivability_collisions(to_commonroad(sub, planning_problem=False)[0]).first_step
    if first < 0:
        return None
    t = (k - 1 + first / factor) * episode.dt
    return f"(the checker on the trajectories interpolated at {sub.dt:g} s: t = {t:.3f} s)"


def _lane_of(episode: EpisodeTrajectories, y: float) -> int:
    return int(np.argmin(np.abs(np.asarray(episode.lanes_y) - y)))


def _checker_only_reason(episode: EpisodeTrajectories, verdict: RefereeVerdict) -> str:
    k = verdict.first_step
    ego_lane = _lane_of(episode, episode.y[0, k])
    names = [episode.names[pid - EGO_ID] for pid in verdict.partners]
    other_lanes = {_lane_of(episode, episode.y[pid - EGO_ID, k]) for pid in verdict.partners}
    if episode.host == "sumo" and ego_lane not in other_lanes:
        return (f"SUMO's list misses it: the ego's centre is in another lane than {', '.join(names)}'s "
                f"(straddling) at step {k}")  # fmt: skip
    return _unexplained(episode, k, names)


def _unexplained(episode: EpisodeTrajectories, k: int, names=()) -> str:
    gaps = []
    for i in range(1, len(episode.names)):
        if episode.present[i, k]:
            gx = abs(episode.x[i, k] - episode.x[0, k]) - 0.5 * (episode.length[i] + episode.length[0])
            gy = abs(episode.y[i, k] - episode.y[0, k]) - 0.5 * (episode.width[i] + episode.width[0])
            gaps.append((max(gx, gy), episode.names[i], gx, gy))
    near = min(gaps) if gaps else None
    where = f"; nearest {near[1]}: gaps x {near[2]:+.4f} m, y {near[3]:+.4f} m (axis-aligned)" if near else ""
    return f"unexplained at step {k}{' with ' + ', '.join(names) if names else ''}{where}"


def referee_episode(episode: EpisodeTrajectories, scenario=None) -> tuple[RefereeVerdict, Agreement]:
    """Export (or take the given ``scenario``, e.g. read back from a file) and referee one episode."""
    if scenario is None:
        from .commonroad import to_commonroad

        scenario, _ = to_commonroad(episode, planning_problem=False)
    verdict = drivability_collisions(scenario)
    return verdict, compare(episode, verdict)
