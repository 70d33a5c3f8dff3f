"""The lane-change scene in highway-env: F and a platoon L1..LN behind a leader L(N+1) that brakes suddenly.

In ``highway-v0`` every vehicle spawns ahead of the ego, so the paper's situation never arises by itself. This
environment (registered as ``safelane/HighwayScene-v0`` by :mod:`safelane.integrations.highway`) builds it on a
straight two-lane road: the ego in lane 1 (right), the target lane 0 (left, highway-env's lane 0 is the leftmost);
F behind the ego and ``L1..LN`` ahead of it in the target lane as highway-env's own IDM vehicles, spaced at IDM's
desired gap (so they cruise until L(N+1) brakes); ``L(N+1)`` a :class:`SuddenBrakeVehicle` braking at ``decel``
from ``brake_at_s`` to a stop; optionally ``L0`` ahead of the ego in its own lane (cruising, or braking as L(N+1)).
Every draw comes from the environment's ``np_random`` (``reset(seed=...)`` reproduces an episode).

Config keys (besides highway-env's; 10 Hz simulation and policy are the defaults here):

``n_leaders`` (N, an int or a list to draw from), ``decel`` (L(N+1)'s deceleration [m/s²], a number or a list),
``brake_at_s`` ((lo, hi) s), ``ego_speed`` ((lo, hi) m/s), ``speed_spread`` (± m/s of the others around the ego's),
``f_gap`` ((lo, hi) m, ego − F centre distance), ``l1_offset`` ((lo, hi) m: L1 − ego beyond IDM's desired gap from
F to L1 is not forced; L1 is placed this far ahead of the ego), ``platoon_slack`` ((lo, hi) m added to IDM's
desired gap between platoon vehicles), ``own_leader`` (``None``, ``"cruise"`` or ``"brake"``), ``own_gap`` ((lo,
hi) m), ``traffic_lane_changes`` (MOBIL on for F and the platoon; off by default: highway-env's MOBIL may move F
or L1 out of the lane mid-manoeuvre), ``duration`` (s).

Connected traffic: ``connected`` (default ``False``: highway-env's traffic is not connected) makes
``L1..LN`` :class:`~.highway_vehicles.PromiseIDMVehicle` — IDM held to the promise ``promise`` [m/s²] (default 0.5)
by the ``worst_case`` leader rule — with ``safelane_connected = True`` and ``safelane_promise``; F too is marked
connected (its IDM unchanged, and it declares no intent: the shield still treats it as aggressive) unless
``connected_follower`` is ``False``. ``L(N+1)`` (and ``L0``) stay non-connected and brake suddenly as before.
"""

from __future__ import annotations

import numpy as np
from highway_env import utils
from highway_env.envs.highway_env import HighwayEnv
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle

from ..tolerances import TIME_TOL_S
from .highway_vehicles import PromiseIDMVehicle, SuddenBrakeVehicle

TARGET_LANE, EGO_LANE = 0, 1


class LaneChangeScene(HighwayEnv):
    """highway-env's ``HighwayEnv`` with the lane-change scene instead of random traffic (see the module)."""

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        utils.update_config(
            config,
            {
                "action": {"type": "ContinuousAction"},
                "simulation_frequency": 10,
                "policy_frequency": 10,
                "lanes_count": 2,
                "duration": 12,
                "n_leaders": [1, 3],
                "decel": [4.0, 6.0, 8.0],
                "brake_at_s": (0.0, 3.0),
                "ego_speed": (20.0, 27.0),
                "speed_spread": 1.0,
                "f_gap": (5.0, 40.0),
                "l1_offset": (0.0, 35.0),
                "platoon_slack": (0.0, 10.0),
                "own_leader": None,
                "own_gap": (25.0, 60.0),
                "traffic_lane_changes": False,
                "connected": False,
                "promise": 0.5,
                "connected_follower": True,
                "x0": 200.0,
            },
        )
        return config

    def _draw(self, key):
        value = self.config[key]
        if isinstance(value, (list, np.ndarray)):
            return value[int(self.np_random.integers(len(value)))]
        if isinstance(value, tuple):
            return float(self.np_random.uniform(*value))
        return value

    def _create_road(self) -> None:
        self.road = Road(
            network=RoadNetwork.straight_road_network(self.config["lanes_count"], speed_limit=40),
            np_random=self.np_random,
            record_history=self.config["show_trajectories"],
        )

    def _idm(self, lane: int, x: float, speed: float, held: bool = False) -> IDMVehicle:
        """highway-env's IDM vehicle; ``held``: a connected :class:`PromiseIDMVehicle` with the config's promise."""
        lane_index = ("0", "1", lane)
        cls, extra = (PromiseIDMVehicle, {"promise": float(self.config["promise"])}) if held else (IDMVehicle, {})
        vehicle = cls(self.road, self.road.network.get_lane(lane_index).position(x, 0.0), 0.0, speed,
                      target_lane_index=lane_index, target_speed=speed,
                      enable_lane_change=bool(self.config["traffic_lane_changes"]), **extra)  # fmt: skip
        vehicle.randomize_behavior()
        return vehicle

    def _create_vehicles(self) -> None:
        net = self.road.network
        n = int(self._draw("n_leaders"))
        decel = float(self._draw("decel"))
        v0 = self._draw("ego_speed")
        spread = float(self.config["speed_spread"])

        def speed():
            return v0 + float(self.np_random.uniform(-spread, spread))

        x_ego = float(self.config["x0"])
        ego_lane = ("0", "1", EGO_LANE)
        ego = self.action_type.vehicle_class(self.road, net.get_lane(ego_lane).position(x_ego, 0.0), 0.0, v0)
        self.controlled_vehicles = [ego]
        self.road.vehicles.append(ego)
        self.scene = {"n_leaders": n, "decel": decel, "roles": {}}

        connected = bool(self.config["connected"])
        self.scene["connected"] = connected
        f = self._idm(TARGET_LANE, x_ego - self._draw("f_gap"), speed())
        if connected and self.config["connected_follower"]:
            f.safelane_connected, f.safelane_promise = True, float(self.config["promise"])
        self.road.vehicles.append(f)
        self.scene["roles"][id(f)] = "F"
        x = x_ego + self._draw("l1_offset")
        for i in range(1, n + 1):
            leader = self._idm(TARGET_LANE, x, speed(), held=connected)
            self.road.vehicles.append(leader)
            self.scene["roles"][id(leader)] = f"L{i}"
            x += leader.desired_gap(leader, leader) + self._draw("platoon_slack")  # IDM's gap at equal speeds
        last = SuddenBrakeVehicle(self.road, net.get_lane(("0", "1", TARGET_LANE)).position(x, 0.0), 0.0, speed(),
                                  decel=decel, brake_at_s=self._draw("brake_at_s"))  # fmt: skip
        self.road.vehicles.append(last)
        self.scene["roles"][id(last)] = f"L{n + 1}"
        own = self.config["own_leader"]
        if own is not None:
            if own not in ("cruise", "brake"):
                raise ValueError(f"config 'own_leader' must be None, 'cruise' or 'brake'; got {own!r}")
            x0 = x_ego + self._draw("own_gap")
            l0 = SuddenBrakeVehicle(self.road, net.get_lane(ego_lane).position(x0, 0.0), 0.0, speed(),
                                    decel=decel if own == "brake" else 0.0,
                                    brake_at_s=self._draw("brake_at_s"))  # fmt: skip
            self.road.vehicles.append(l0)
            self.scene["roles"][id(l0)] = "L0"

    def _is_truncated(self) -> bool:
        return self.time >= self.config["duration"] - TIME_TOL_S
