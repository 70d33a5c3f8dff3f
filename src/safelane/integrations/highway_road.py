"""What :class:`~.highway.SafeLaneShield` reads from a highway-env road: whether the host fits the shield (its
frequencies, straight lanes of the right width), a vehicle's longitudinal state, the ego's own-lane leaders, and,
on a crash, who hit whom (:func:`classify_crash`, :func:`crash_partner`) and the vehicles' states for the blame rule
(:func:`blame_tracks`). Needs highway-env (extra ``highway``).
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..shield import LaneFrame
from ..shield.world import Others

try:
    from highway_env.road.lane import StraightLane
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError('safelane.integrations.highway needs highway-env: pip install "safelane[highway]"') from exc


def highway_params(**overrides) -> Params:
    """:class:`Params` for highway-env's geometry and traffic: 4 m lanes, 5 × 2 m vehicles, and ``a_x_a = 3`` m/s²
    (IDM's largest acceleration, ``COMFORT_ACC_MAX``: an aggressive F accelerates at most at it). ``a_x_d`` stays 8
    m/s² (IDM brakes at up to 6; the scene's L(N+1) at up to 8)."""
    values = {"lane_width": 4.0, "vehicle_width": 2.0, "vehicle_length": 5.0, "a_x_a": 3.0}
    values.update(overrides)
    return Params(**values)


def check_frequencies(env, params: Params) -> None:
    """Raise a ``ValueError`` naming the config keys unless the host simulates and decides every ``params.dt``."""
    config = env.unwrapped.config
    hz = 1.0 / params.dt
    sim, pol = config.get("simulation_frequency"), config.get("policy_frequency")
    if not (np.isclose(sim, hz) and np.isclose(pol, hz)):
        raise ValueError(
            f"SafeLaneShield needs a {hz:g} Hz simulation and a {hz:g} Hz policy (the shield's period Params.dt = "
            f"{params.dt:g} s); this env has config['simulation_frequency'] = {sim!r} and config['policy_frequency'] "
            f"= {pol!r}. Make it with config={{'simulation_frequency': {hz:g}, 'policy_frequency': {hz:g}}}, e.g. "
            f"gymnasium.make('highway-v0', config=safelane.integrations.highway.HIGHWAY_CONFIG)"
        )


def check_road(road, params: Params) -> None:
    """Raise a ``ValueError`` naming the lane unless every lane is straight along +x and ``params.lane_width`` wide."""
    for _from, to in road.network.graph.items():
        for _to, lanes in to.items():
            for i, lane in enumerate(lanes):
                heading = getattr(lane, "heading", np.nan)
                if not (isinstance(lane, StraightLane) and abs(np.sin(heading)) < 1e-9 and np.cos(heading) > 0):
                    name = type(lane).__name__
                    raise ValueError(f"SafeLaneShield supports straight roads along +x (highway-v0's); lane "
                                     f"{(_from, _to, i)} is a {name} (heading {heading:.3f})")  # fmt: skip
                if not np.isclose(lane.width, params.lane_width):
                    raise ValueError(f"lane {(_from, _to, i)} is {lane.width} m wide but Params.lane_width = "
                                     f"{params.lane_width}: use highway_params(lane_width={lane.width})")  # fmt: skip


def longitudinal(vehicle) -> tuple[float, float]:
    """``(x, v_x)`` of a host vehicle; a negative speed (highway-env lets IDM vehicles reverse) reads as 0."""
    speed = getattr(vehicle, "speed", 0.0) * np.cos(getattr(vehicle, "heading", 0.0))
    return float(vehicle.position[0]), max(float(speed), 0.0)


def own_lane_leaders(road, ego, lane_index, k: int = 1) -> tuple[np.ndarray, np.ndarray, list]:
    """The ego's own-lane leaders ``L0, …`` (nearest first, ``k`` of them): ``(x (k,), v (k,), vehicles)``, with
    ``np.inf`` positions (and speed 0) where there is none. The one place the own lane is read (docs/real_roads.md)."""
    x, v, found = np.full(k, np.inf), np.zeros(k), []
    current = ego
    for i in range(k):
        front, _ = road.neighbour_vehicles(current, lane_index)
        if front is None:
            break
        x[i], v[i] = longitudinal(front)
        found.append(front)
        current = front
    return x, v, found


def crash_partner(ego, road):
    """The ego's collision partner: the nearest other vehicle with highway-env's ``crashed`` flag (``None``: none)."""
    others = [v for v in road.vehicles if v is not ego and getattr(v, "crashed", False)]
    if not others:
        return None
    return min(others, key=lambda v: float(np.linalg.norm(v.position - ego.position)))


def blame_tracks(ego, vehicles):
    """The ego and ``vehicles`` as :class:`safelane.blame.Track` s in highway-env's road frame (``x`` along the
    straight road, ``y`` to the right: the blame rule is symmetric in ``y``), velocities from highway-env's
    ``velocity`` (the point-mass ego's is ``(speed, lateral_speed)``)."""
    from ..blame import Track

    def track(vs):
        vel = np.array([v.velocity for v in vs], float).reshape(-1, 2)
        pos = np.array([v.position for v in vs], float).reshape(-1, 2)
        size = np.array([(v.LENGTH, v.WIDTH) for v in vs], float).reshape(-1, 2)
        return Track(pos[:, 0], pos[:, 1], vel[:, 0], vel[:, 1], size[:, 0], size[:, 1])

    return Track(*(q[0] for q in track([ego]))), track(vehicles)


def classify_crash(ego, road, roles: dict, frame: LaneFrame, params: Params, original_lane, target_lane) -> dict:
    """Who hit whom, where: the ego's collision partner (the nearest crashed vehicle), its role (``F``, ``L1``,
    ``L0``, … from ``roles``: vehicle id → name, else ``other``), its lane (``target``, ``original``, ``other``),
    the ego's lateral phase (``original lane``, ``straddling``, ``target lane``), the kind of contact, and whether
    the partner was changing lanes (e.g. MOBIL cutting in from the lane beyond the target lane)."""
    y, _ = frame.y(ego.position[1], 0.0)
    y = float(y)
    phase = "original lane" if y <= params.y_safe else ("target lane" if y >= params.lane_width - params.y_safe
                                                          else "straddling")  # fmt: skip
    partner = crash_partner(ego, road)
    if partner is None:
        return {"partner": "none", "lane": "-", "ego_phase": phase, "kind": "unknown"}
    lane_id = partner.lane_index[2] if partner.lane_index else None
    lane = "target" if lane_id == target_lane[2] else ("original" if lane_id == original_lane[2] else "other")
    dx = float(partner.position[0] - ego.position[0])
    length = 0.5 * (ego.LENGTH + partner.LENGTH)
    if abs(dx) < 0.8 * length:
        kind = "side contact"
    elif dx > 0:
        kind = "ego ran into it (ahead)"
    else:
        kind = "it ran into the ego (behind)"
    changing = abs(float(getattr(partner, "heading", 0.0))) > 1e-3 or (
        getattr(partner, "target_lane_index", partner.lane_index) != partner.lane_index)  # fmt: skip
    return {"partner": roles.get(id(partner), "other"), "lane": lane, "ego_phase": phase, "kind": kind,
            "partner_changing_lanes": bool(changing),
            "dx_m": round(dx, 2), "partner_speed": round(float(partner.speed), 2),
            "ego_speed": round(float(ego.speed), 2)}  # fmt: skip


def road_others(road, taken, frame: LaneFrame) -> Others:
    """Every road vehicle whose id is not in ``taken`` (the ego, F, the chain, the own-lane leaders) as an
    :class:`~safelane.shield.world.Others` row in the shield's frame (``frame``): centre, velocity (highway-env's
    ``velocity``, its speed along its heading; a reversing vehicle's ``v_x`` reads as 0), not connected. At least one
    slot (``+inf`` padding where there is no other vehicle)."""
    rest = [v for v in road.vehicles if id(v) not in taken]
    if not rest:
        return Others.empty(1, 1)
    pos = np.array([v.position for v in rest], float).reshape(-1, 2)
    vel = np.array([v.velocity for v in rest], float).reshape(-1, 2)
    y, vy = frame.y(pos[:, 1], vel[:, 1])
    return Others.from_arrays(pos[None, :, 0], y[None, :], np.maximum(vel[None, :, 0], 0.0), vy[None, :])
