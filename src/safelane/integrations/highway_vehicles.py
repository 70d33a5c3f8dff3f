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
from .highway_road import highway_params


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


class PromiseIDMVehicle(IDMVehicle):
    """A connected highway-env IDM vehicle held to its V2X promise (the scene's ``L1..LN`` with ``connected``).

    Each period it takes IDM's acceleration as its own driving task and filters it by the simulator's ``worst_case``
    leader rule (:func:`safelane.sim.behaviours.leader_accels`): its *chain bound* — ``max(promise, needed)``
    capped at ``a_x_d``, from :func:`safelane.safety.leader_chain` over its own lane's true states from itself up to
    the first vehicle that is not connected (``a_x_d`` for that one) — is the hardest it ever brakes, and it brakes
    beyond IDM's wish (up to that bound, past IDM's ±6 m/s² clip) where a safe distance to the vehicle ahead's own
    bound needs it. So no connected leader brakes harder than the bound the ego's chain analysis gives it. With
    nothing ahead it brakes at no more than its promise.

    Its longitudinal motion is exact (piecewise-constant acceleration, stopping at 0) while it drives straight
    (heading and steering 0, as in the scene without MOBIL); otherwise, or once crashed, highway-env's integration.
    Attributes: ``safelane_connected`` (True), ``safelane_promise`` [m/s²], ``safelane_params`` (the
    :class:`~safelane.params.Params` of the rule; default ``highway_params()``), ``safelane_bound`` (the bound of the
    last period).
    """

    safelane_connected = True

    def __init__(self, *args, promise: float = 0.5, params=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.safelane_promise = float(promise)
        self.safelane_params = params
        self.safelane_bound = np.nan

    def _params(self):
        if self.safelane_params is None:
            self.safelane_params = highway_params()
        return self.safelane_params

    def platoon_ahead(self) -> list:
        """This vehicle, the connected vehicles ahead of it in its lane, and the first one that is not (if any)."""
        chain, current = [self], self
        while len(chain) < 64:
            front, _ = self.road.neighbour_vehicles(current, self.lane_index)
            if front is None:
                break
            chain.append(front)
            if not getattr(front, "safelane_connected", False):
                break
            current = front
        return chain

    def held_accel(self, task: float) -> float:
        """``task`` filtered by the ``worst_case`` leader rule (see the class docstring); sets ``safelane_bound``."""
        from ..safety import leader_chain
        from ..sim.behaviours import leader_accels, leader_roles

        prm = self._params()
        promise = min(max(self.safelane_promise, 0.0), prm.a_x_d)
        chain = self.platoon_ahead()
        if len(chain) == 1:
            self.safelane_bound = promise
            return max(task, -promise)
        x = np.array([float(v.position[0]) for v in chain])
        v = np.array([max(float(v.speed * np.cos(v.heading)), 0.0) for v in chain])
        promises = np.array([min(max(float(getattr(c, "safelane_promise", prm.a_x_d)), 0.0), prm.a_x_d)
                             for c in chain[:-1]])  # fmt: skip
        bounds = np.asarray(leader_chain(x, v, promises, prm).decel, float)
        self.safelane_bound = float(bounds[0])
        k = len(chain) + 1  # slot 0: a placeholder F (leader_accels' layout), then self, …, the non-connected one
        xs = np.concatenate(([x[0] - 1e6], x))[None, :]
        vs = np.concatenate(([0.0], v))[None, :]
        valid = np.ones((1, k), bool)
        roles = leader_roles(valid, valid, np.array([k - 2]))
        task_row = np.zeros((1, k))
        task_row[0, 1] = task
        acc = leader_accels(xs, vs, np.full((1, k), prm.p_m), roles,
                            np.concatenate(([prm.a_x_d], bounds))[None, :], task_row, np.zeros(1),
                            np.array([prm.a_x_d]), None, None, prm)  # fmt: skip
        return float(acc[0, 1])

    def act(self, action=None) -> None:
        super().act(action)
        if self.crashed:
            return
        self.action["acceleration"] = self.held_accel(float(self.action["acceleration"]))

    def step(self, dt: float) -> None:
        straight = abs(float(self.heading)) < 1e-9 and abs(float(self.action.get("steering", 0.0))) < 1e-9
        if not straight or self.crashed:
            super().step(dt)
            return
        x, v = advance(float(self.position[0]), max(float(self.speed), 0.0), float(self.action["acceleration"]), dt)
        self.timer += dt
        self.position = np.array([float(x), float(self.position[1])])
        self.speed = float(v)
        if self.impact is not None:
            self.position += self.impact
            self.crashed = True
            self.impact = None
        self.on_state_update()
