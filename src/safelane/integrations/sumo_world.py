"""The SUMO side of :mod:`safelane.integrations.sumo`: starting libsumo (or TraCI), writing an episode's routes,
reading vehicles per lane, commanding them, and SUMO's own collision list.

Facts about SUMO this module is built around (measured with libsumo 1.28; the tests re-check the ones that matter):

* positions are **front bumpers** (``getLanePosition``, ``moveToXY``); safelane's reference points are centres:
  ``centre = front − length/2`` (:func:`front_to_centre`, :func:`centre_to_front`), in one place;
* a vehicle SUMO refuses to insert (the default insertion checks refuse a 17 m gap at 30 m/s) is silently pending
  and its getters return ``−2^30``: routes are written with ``insertionChecks="none"``, and :meth:`SumoWorld.load`
  checks that every vehicle was inserted;
* with the default speed mode SUMO caps braking at ``decel``; vehicles driven from Python get speed mode 0 and a
  speed command per step (``setSpeed``), which under ballistic integration moves them exactly as constant
  acceleration over the step — except a stop inside the step, where SUMO advances ``v·dt/2`` instead of
  ``v²/(2a)`` (at most ``a·dt²/8`` = 1 cm at 8 m/s², the vehicle ending ahead of the exact stop);
  ``setAcceleration`` is not used (with speed mode 0 it did not brake at the commanded rate);
* ``moveToXY(..., keepRoute=2)`` puts the front bumper exactly at the given point at the next step (the vehicle does
  not move further in that step), with any lateral offset (the sublane model on);
* SUMO's collision list registers a pair only when **both centres lie in the same lane**: an ego straddling the lane
  boundary with its centre in lane 0 that overlaps a lane-1 vehicle by up to 0.9 m is not reported (measured;
  :func:`overlaps` is our geometric cross-check, reported next to SUMO's list, never instead of it);
* one simulation per process (libsumo is a process-wide singleton): :class:`SumoWorld` refuses a second one.
"""

from __future__ import annotations

import atexit
import importlib
import shutil
import tempfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from ..params import Params
from ..tolerances import TIME_TOL_S

EDGE = "road"
ROUTE = "r"
LANES = ("road_0", "road_1")  # lane 0: the ego's original lane (SUMO's rightmost); lane 1: the target lane
INSTALL_HINT = "SUMO integration needs libsumo: pip install 'safelane[sumo]' (or pip install libsumo)"

_ACTIVE: SumoWorld | None = None  # libsumo allows one simulation per process


def net_file() -> Path:
    """The shipped network (``tools/make_sumo_net.py`` regenerates it): a straight two-lane road along +x."""
    return Path(str(resources.files("safelane.integrations") / "data" / "straight2.net.xml"))


def libsumo_available() -> bool:
    try:
        importlib.import_module("libsumo")
    except ImportError:
        return False
    return True


def import_api(traci: bool = False):
    """``libsumo`` (default: in-process, fast) or ``traci`` (a SUMO process; needs a SUMO binary), with the install
    hint when missing."""
    name = "traci" if traci else "libsumo"
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        hint = "TraCI needs the traci package and a SUMO binary: pip install eclipse-sumo" if traci else INSTALL_HINT
        raise ImportError(f"{hint} ({exc})") from exc


def front_to_centre(front, length: float):
    """SUMO's front-bumper position → safelane's reference point (the centre)."""
    return np.asarray(front, float) - 0.5 * length


def centre_to_front(centre, length: float):
    """safelane's centre → SUMO's front-bumper position."""
    return np.asarray(centre, float) + 0.5 * length


@dataclass(frozen=True)
class VehicleSpec:
    """One vehicle of an episode's route file: ``lane`` 0 or 1, centre position ``x`` [m] (road frame), speed."""

    vid: str
    lane: int
    x: float
    v: float


@dataclass(frozen=True)
class LaneRead:
    """The vehicles of one lane at one step, sorted by position: ids, centres, speeds, lateral centres (road y)."""

    ids: tuple[str, ...]
    x: np.ndarray
    v: np.ndarray
    y: np.ndarray


def sumo_args(net: Path, routes: Path, params: Params, *, lateral_resolution: float, fcd: str | None,
              seed: int) -> list[str]:  # fmt: skip
    """The command line every run uses (the settings the integration's guarantees rest on)."""
    args = [
        "-n", str(net), "-r", str(routes),
        "--step-length", repr(params.dt),
        "--step-method.ballistic", "true",
        "--collision.action", "warn",
        "--collision.mingap-factor", "0",
        "--collision.check-junctions", "true",
        "--lateral-resolution", repr(lateral_resolution),
        "--default.action-step-length", repr(params.dt),
        "--seed", str(seed),
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--begin", "0",
    ]  # fmt: skip
    if fcd:
        args += ["--fcd-output", fcd, "--fcd-output.geo", "false"]
    return args


def routes_xml(vehicles: list[VehicleSpec], params: Params) -> str:
    """An episode's route file: one vehicle type of ``Params``' size and limits, one route, every vehicle departing at
    ``t = 0`` without insertion checks at its exact position (front bumper) and speed."""
    lines = [
        "<routes>",
        f'    <vType id="car" length="{params.vehicle_length!r}" width="{params.vehicle_width!r}" minGap="0" '
        f'accel="{params.a_x_a!r}" decel="{params.a_x_d!r}" emergencyDecel="{params.a_x_d!r}" '
        f'apparentDecel="{params.a_x_d!r}" sigma="0" tau="1.0" maxSpeed="50" speedFactor="1" '
        'latAlignment="center" lcStrategic="-1" lcSpeedGain="0" lcKeepRight="0" lcCooperative="-1"/>',
        f'    <route id="{ROUTE}" edges="{EDGE}"/>',
    ]
    for veh in vehicles:
        front = float(centre_to_front(veh.x, params.vehicle_length))
        lines.append(
            f'    <vehicle id="{veh.vid}" type="car" route="{ROUTE}" depart="0" departLane="{veh.lane}" '
            f'departPos="{front!r}" departSpeed="{veh.v!r}" departPosLat="center" insertionChecks="none"/>'
        )
    lines.append("</routes>")
    return "\n".join(lines) + "\n"


class SumoWorld:
    """One SUMO simulation in this process, reloaded for every episode (``load``: ~5 ms for the shipped network).

    libsumo is a process-wide singleton: a second :class:`SumoWorld` while one is open raises; run parallel
    episodes in separate processes (``benchmarks/sumo_campaign.py --workers``).
    """

    def __init__(
        self,
        params: Params | None = None,
        *,
        traci: bool = False,
        gui: bool = False,
        lateral_resolution: float = 0.25,
        fcd: str | None = None,
        seed: int = 0,
        net: Path | None = None,
    ):
        global _ACTIVE
        if _ACTIVE is not None:
            raise RuntimeError("a SUMO simulation is already open in this process (libsumo allows one per process): "
                               "close it first (SumoWorld.close) or run episodes in separate processes")  # fmt: skip
        self.params = params or Params()
        self.api = import_api(traci or gui)
        self.binary = "sumo-gui" if gui else "sumo"
        self.lateral_resolution = float(lateral_resolution)
        self.fcd, self.seed = fcd, int(seed)
        self.net = Path(net) if net is not None else net_file()
        self._tmp = Path(tempfile.mkdtemp(prefix="safelane-sumo-"))
        self.routes = self._tmp / "episode.rou.xml"
        self.started = False
        self.lane_y = (0.0, 0.0)
        self._settings: dict | None = None  # read back from SUMO when it first starts (settings())
        _ACTIVE = self
        atexit.register(self.close)

    # -- life cycle ---------------------------------------------------------------------------------------------
    def load(self, vehicles: list[VehicleSpec], sumo_controlled: frozenset[str] = frozenset()) -> None:
        """Start (first call) or reload SUMO with these vehicles, step once (they appear at ``t = 0.1`` s in SUMO's
        clock, at their exact initial states: the episode's ``t = 0``), and hand every vehicle not in
        ``sumo_controlled`` to Python (speed mode 0, no lane changes of SUMO's)."""
        self.routes.write_text(routes_xml(vehicles, self.params))
        args = sumo_args(self.net, self.routes, self.params, lateral_resolution=self.lateral_resolution,
                         fcd=self.fcd, seed=self.seed)  # fmt: skip
        if not self.started:
            self.api.start([self._binary(), *args])
            self.started = True
            shapes = [self.api.lane.getShape(lane) for lane in LANES]
            self.lane_y = tuple(float(s[0][1]) for s in shapes)
            self._settings = self._read_settings()
        else:
            self.api.load(args)
        self.api.simulationStep()
        present = set(self.api.vehicle.getIDList())
        missing = [veh.vid for veh in vehicles if veh.vid not in present]
        if missing:
            raise RuntimeError(f"SUMO did not insert {missing} (pending: {self.api.simulation.getPendingVehicles()})")
        for veh in vehicles:
            self.api.vehicle.setLaneChangeMode(veh.vid, 0)
            if veh.vid not in sumo_controlled:
                self.api.vehicle.setSpeedMode(veh.vid, 0)
            else:
                self.api.vehicle.setMaxSpeed(veh.vid, max(veh.v, 0.1))  # SUMO's own driver keeps its initial speed

    def _binary(self) -> str:
        if self.api.__name__ == "libsumo":
            return self.binary
        try:
            import sumo  # eclipse-sumo

            return str(Path(sumo.SUMO_HOME) / "bin" / self.binary)
        except ImportError:
            return shutil.which(self.binary) or self.binary

    def close(self) -> None:
        global _ACTIVE
        if self.started:
            try:
                self.api.close()
            except Exception:  # closing an already closed connection
                pass
            self.started = False
        shutil.rmtree(self._tmp, ignore_errors=True)
        if _ACTIVE is self:
            _ACTIVE = None

    def __enter__(self) -> SumoWorld:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- reading ------------------------------------------------------------------------------------------------
    def time(self) -> float:
        return float(self.api.simulation.getTime())

    def settings(self) -> dict:
        """What SUMO itself reports for the settings the integration relies on (read back, not echoed): read when
        the first :meth:`load` starts SUMO (every episode reloads it with the same options), so available from then
        on, after :meth:`close` too; before, a ``RuntimeError`` that says so."""
        if self._settings is None:
            raise RuntimeError("SUMO settings are read back from SUMO when it starts, i.e. after the first episode "
                               "has been loaded: call settings() after runner.run(...) / run_many(...) (inside or "
                               "after the with block), or after SumoWorld.load(...)")  # fmt: skip
        return {k: list(v) if isinstance(v, list) else v for k, v in self._settings.items()}

    def _read_settings(self) -> dict:
        opt = self.api.simulation.getOption
        return {
            "step_length_s": float(self.api.simulation.getDeltaT()),
            "ballistic": opt("step-method.ballistic"),
            "collision_action": opt("collision.action"),
            "collision_mingap_factor": float(opt("collision.mingap-factor")),
            "lateral_resolution_m": float(opt("lateral-resolution")),
            "lane_width_m": [float(self.api.lane.getWidth(lane)) for lane in LANES],
            "lane_centre_y_m": list(self.lane_y),
        }

    def lane(self, index: int, exclude: str = "") -> LaneRead:
        """The vehicles whose centre SUMO puts in lane ``index``, sorted by position (centres), ``exclude`` left out."""
        veh = self.api.vehicle
        ids = [vid for vid in self.api.lane.getLastStepVehicleIDs(LANES[index]) if vid != exclude]
        length = self.params.vehicle_length
        x = front_to_centre(np.array([veh.getLanePosition(vid) for vid in ids], float), length)
        v = np.array([veh.getSpeed(vid) for vid in ids], float)
        y = np.array([veh.getLateralLanePosition(vid) for vid in ids], float) + self.lane_y[index]
        order = np.argsort(x, kind="stable")
        return LaneRead(tuple(ids[i] for i in order), x[order], v[order], y[order])

    def position(self, vid: str) -> tuple[float, float]:
        """``(centre x, y)`` of a vehicle in the road frame."""
        px, py = self.api.vehicle.getPosition(vid)
        return float(front_to_centre(px, self.params.vehicle_length)), float(py)

    def collisions(self) -> list[dict]:
        """SUMO's own collision list for the last step."""
        return [
            {"collider": c.collider, "victim": c.victim, "type": c.type, "lane": c.lane, "pos": float(c.pos)}
            for c in self.api.simulation.getCollisions()
        ]

    # -- commanding ---------------------------------------------------------------------------------------------
    def set_speed(self, vid: str, speed: float) -> None:
        self.api.vehicle.setSpeed(vid, max(float(speed), 0.0))

    def place(self, vid: str, x_centre: float, y_road: float, speed: float) -> None:
        """Put a vehicle (the ego) at an exact centre position and speed for the next step (``moveToXY`` with any
        lateral offset; the body stays aligned with the road, as the shield's point-mass model assumes)."""
        front = float(centre_to_front(x_centre, self.params.vehicle_length))
        self.api.vehicle.moveToXY(vid, EDGE, -1, front, float(y_road), angle=90.0, keepRoute=2)
        self.api.vehicle.setSpeed(vid, max(float(speed), 0.0))

    def step(self) -> None:
        self.api.simulationStep()


def overlaps(x, y, params: Params, pairs) -> list[tuple[int, int, float, float]]:
    """Our geometric cross-check: axis-aligned bodies (``vehicle_length × vehicle_width`` at the centres) that overlap
    with positive area; ``pairs`` ``(i, j)`` index ``x``/``y``. Returns ``(i, j, longitudinal gap, lateral gap)``."""
    out = []
    for i, j in pairs:
        gx = abs(x[i] - x[j]) - params.vehicle_length
        gy = abs(y[i] - y[j]) - params.vehicle_width
        if gx < 0.0 and gy < 0.0:
            out.append((i, j, float(gx), float(gy)))
    return out


def braking_parity(world: SumoWorld, v0: float = 30.0, decel: float = 8.0, seconds: float = 6.0) -> dict:
    """Our point-mass kinematics against SUMO's for the trivial scenario: one vehicle braking at a constant ``decel``
    from ``v0`` until it stops (speed commands per step, ballistic integration). Returns the largest position and
    speed differences before the stop, at and after it, and the bound SUMO's stop step allows (``decel·dt²/8``)."""
    from .._motion import advance

    prm = world.params
    dt = prm.dt
    x0 = 100.0
    world.load([VehicleSpec("probe", 0, x0, v0)])
    t_stop = v0 / decel
    err_moving = err_stopped = err_v = 0.0
    for k in range(1, round(seconds / dt) + 1):
        v = world.api.vehicle.getSpeed("probe")
        world.set_speed("probe", max(v - decel * dt, 0.0))
        world.step()
        x_ref, v_ref = advance(np.float64(x0), np.float64(v0), np.float64(-decel), k * dt)
        x_sumo = float(front_to_centre(world.api.vehicle.getLanePosition("probe"), prm.vehicle_length))
        err = abs(x_sumo - float(x_ref))
        err_v = max(err_v, abs(world.api.vehicle.getSpeed("probe") - float(v_ref)))
        if k * dt < t_stop - TIME_TOL_S:
            err_moving = max(err_moving, err)
        else:
            err_stopped = max(err_stopped, err)
    return {"v0_mps": v0, "decel_mps2": decel, "max_pos_err_moving_m": err_moving,
            "max_pos_err_stopped_m": err_stopped, "max_speed_err_mps": err_v,
            "stop_bound_m": decel * dt * dt / 8.0}  # fmt: skip
