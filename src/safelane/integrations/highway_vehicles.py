"""highway-env vehicle classes of ours: the ego as an exact point mass, a leader that brakes suddenly, and IDM
traffic that does not cut in beside or ahead of the ego while it changes lanes.

highway-env's :class:`~highway_env.vehicle.kinematics.Vehicle` integrates the position with the period's *old* speed
(explicit Euler: braking at 8 m/s² from 25 m/s for 3 s overshoots by 1.2 m at 10 Hz, the unsafe side for the ego)
and lets speeds go negative. The shield's guarantee is about exact piecewise-constant-acceleration motion, so the ego
moves as :class:`PointMassVehicle`: ``x`` and ``y`` integrated exactly, the speed stopping at zero, the heading kept
at the lane's (0: a box aligned with the road, the shield's geometry). Importing this module imports highway-env.
"""

from __future__ import annotations

import numpy as np
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle

from .._motion import advance


class PointMassVehicle(Vehicle):
    """The ego: an exact point mass on a straight road along ``+x`` (highway-env's frame: ``y`` grows to the right).

    Each period it executes :attr:`command`, set by the caller before the host steps:

    * ``("accel", a_x, a_y)`` — constant accelerations (highway-env frame) for the period; the speed stops at 0;
    * ``("state", x, vx, y, vy)`` — the exact state at the period's end (an aborting shield's plan, evaluated
      exactly with its switches inside the period).

    ``speed`` is the longitudinal speed ``v_x`` (never negative), ``lateral_speed`` is ``v_y``; ``heading`` stays 0.
    """

    def __init__(self, road, position, heading: float = 0.0, speed: float = 0.0, lateral_speed: float = 0.0):
        super().__init__(road, position, 0.0, max(float(speed), 0.0))
        self.lateral_speed = float(lateral_speed)
        self.command: tuple = ("accel", 0.0, 0.0)

    @classmethod
    def replacing(cls, vehicle: Vehicle) -> PointMassVehicle:
        """A point mass at ``vehicle``'s position and (longitudinal) speed, with no lateral speed."""
        vx = float(vehicle.speed * np.cos(vehicle.heading))
        ego = cls(vehicle.road, np.array(vehicle.position, float), 0.0, vx, 0.0)
        if hasattr(vehicle, "color"):
            ego.color = vehicle.color
        return ego

    @property
    def velocity(self) -> np.ndarray:
        return np.array([self.speed, self.lateral_speed])

    def act(self, action=None) -> None:
        """highway-env's action types call this with their own action; the command set by the caller is kept."""

    def step(self, dt: float) -> None:
        kind = self.command[0]
        if kind == "accel":
            _, a_x, a_y = self.command
            x, vx = advance(self.position[0], self.speed, a_x, dt)
            y = self.position[1] + self.lateral_speed * dt + 0.5 * a_y * dt * dt
            vy = self.lateral_speed + a_y * dt
        elif kind == "state":
            _, x, vx, y, vy = self.command
        else:
            raise ValueError(f"PointMassVehicle.command must be ('accel', a_x, a_y) or ('state', x, vx, y, vy); "
                             f"got {self.command!r}")  # fmt: skip
        self.position = np.array([float(x), float(y)])
        self.speed, self.lateral_speed = max(float(vx), 0.0), float(vy)
        if self.impact is not None:  # highway-env's collision response (as Vehicle.step applies it)
            self.position += self.impact
            self.crashed = True
            self.impact = None
        self.on_state_update()


class SuddenBrakeVehicle(Vehicle):
    """A leader on a straight lane that cruises at its speed, then brakes at ``decel`` from ``brake_at_s`` until it
    stops (exact point mass, no lane changes; IDM followers see it as any vehicle). The scene's L(N+1)."""

    def __init__(self, road, position, heading: float = 0.0, speed: float = 0.0, decel: float = 0.0,
                 brake_at_s: float = 0.0):  # fmt: skip
        super().__init__(road, position, 0.0, max(float(speed), 0.0))
        self.decel = float(decel)
        self.brake_at_s = float(brake_at_s)
        self.clock = 0.0

    def act(self, action=None) -> None:
        """Its motion is its profile."""

    def step(self, dt: float) -> None:
        t0, t1 = self.clock, self.clock + dt
        x, v = self.position[0], self.speed
        cruise = min(max(self.brake_at_s - t0, 0.0), dt)  # the part of the period before the braking starts
        x = x + v * cruise
        if t1 > self.brake_at_s:
            x, v = advance(x, v, -self.decel, dt - cruise)
        self.position = np.array([float(x), float(self.position[1])])
        self.speed = float(v)
        self.clock = t1
        if self.impact is not None:
            self.position += self.impact
            self.crashed = True
            self.impact = None
        self.on_state_update()


class NoCutInIDMVehicle(IDMVehicle):
    """highway-env's IDM/MOBIL vehicle, except that it starts no lane change that :func:`cuts_in` — into the ego's
    target or original lane, beside the ego or between it and its nearest leader there — while the ego's lane change
    is under way: the paper's assumption that F, L1 and L0 are the ego's neighbours throughout. Every other MOBIL
    decision is highway-env's (lane changes behind the ego, beyond its leaders, between other lanes).

    Use it as ``config["other_vehicles_type"]`` (:data:`~safelane.integrations.highway.NO_CUT_IN_CONFIG`).
    :class:`~safelane.integrations.highway.SafeLaneShield` publishes the manoeuvre as ``road.safelane_manoeuvre``
    (``(ego, (original_lane_index, target_lane_index))`` until the ego lies wholly in the target lane, then
    ``None``); without it the vehicle is an ordinary ``IDMVehicle``.
    """

    def mobil(self, lane_index) -> bool:
        if cuts_in(self, lane_index):
            return False
        return super().mobil(lane_index)


def is_behind(vehicle, ego) -> bool:
    """``vehicle`` lies wholly behind ``ego`` (its front bumper behind the ego's rear bumper)."""
    return float(vehicle.position[0]) + 0.5 * vehicle.LENGTH < float(ego.position[0]) - 0.5 * ego.LENGTH


def cuts_in(vehicle, lane_index) -> bool:
    """Whether ``vehicle`` moving into ``lane_index`` cuts in on the ego's manoeuvre published on its road: the lane
    is the ego's target or original lane, the vehicle is not wholly behind the ego, and it is not wholly ahead of
    the ego's nearest leader in that lane (there is none, the vehicle is that leader, or it would come closer)."""
    manoeuvre = getattr(vehicle.road, "safelane_manoeuvre", None)
    if manoeuvre is None:
        return False
    ego, lanes = manoeuvre
    if vehicle is ego or tuple(lane_index) not in lanes or is_behind(vehicle, ego):
        return False
    front, _ = vehicle.road.neighbour_vehicles(ego, lane_index)
    if front is None or front is vehicle:
        return True
    return float(vehicle.position[0]) - 0.5 * vehicle.LENGTH <= float(front.position[0]) + 0.5 * front.LENGTH
