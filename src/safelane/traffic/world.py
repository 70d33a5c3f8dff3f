"""The SUMO side of a traffic-level run: start libsumo on the merge network, read every vehicle as arrays each
period (subscriptions), command the vehicles under the shield, and SUMO's own collision list.

Positions are SUMO's **front bumpers** in network coordinates; they become centres (safelane's reference points)
here, in one place (:func:`safelane.integrations.sumo_world.front_to_centre`). The mainline runs along +x, so a
vehicle's centre is ``x − length/2`` and its lane (from the left) follows from ``y`` (:func:`.demand.lane_of`).
Lateral speeds are SUMO's own (``VAR_SPEED_LAT``, positive to the left, i.e. toward +y on this network): zero for
its instantaneous lane changes, the lane change's lateral speed with ``Demand.lc_duration_s > 0``.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..integrations.sumo_world import centre_to_front, front_to_centre, import_api
from ..params import Params
from . import demand as dem

#: Speed mode of SUMO's own drivers (all safety checks on) and of vehicles driven from Python (none).
SPEED_MODE_SUMO, SPEED_MODE_OURS = 31, 0


@dataclass(frozen=True)
class Fleet:
    """Every vehicle in the network at the start of a period (``(V,)`` arrays, SUMO's order)."""

    ids: tuple[str, ...]
    x: np.ndarray  # centre along the road [m]
    y: np.ndarray  # road y of the centre line [m]
    v: np.ndarray
    a: np.ndarray
    lane: np.ndarray  # lane from the left (demand.lane_of); -1 on the ramp
    equipped: np.ndarray
    vy: np.ndarray | None = None  # SUMO's lateral speed [m/s], road frame (+y: to the left); None: zeros

    def __len__(self) -> int:
        return len(self.ids)


class TrafficWorld:
    """One libsumo simulation of the merge network with a demand (one per process: libsumo is a singleton)."""

    def __init__(self, demand: dem.Demand, params: Params | None = None, *, net: Path | None = None,
                 ssm: bool = True, routes: str | None = None):  # fmt: skip
        self.params = params or Params()
        self.api = import_api()
        self._tmp = tempfile.TemporaryDirectory(prefix="safelane-traffic-")
        tmp = Path(self._tmp.name)
        self.routes = tmp / "run.rou.xml"
        self.routes.write_text(routes if routes is not None else dem.routes_xml(demand, self.params))
        self.ssm_file = tmp / "ssm.xml" if ssm else None
        args = dem.sumo_args(net or dem.net_file(), self.routes, self.ssm_file, self.params, demand.seed,
                             demand.seconds, demand.lc_duration_s)  # fmt: skip
        self.api.start(["sumo", *args])
        #: x of the network's end (where every vehicle leaves): the end of the last edge, ``out``
        self.end_x = float(self.api.lane.getShape("out_0")[-1][0])
        tc = self.api.constants
        self._vars = (tc.VAR_POSITION, tc.VAR_SPEED, tc.VAR_ACCELERATION, tc.VAR_ROAD_ID, tc.VAR_SPEED_LAT)
        self.equipped: set[str] = set()
        self.taken: set[str] = set()  # driven from Python (the shield's changers)
        self._v_now: dict[str, float] = {}  # speeds of the last read
        self._floors: dict[str, tuple[float, float]] = {}  # vid -> (speed floor, decel) for the next step
        self._lag: dict[str, float] = {}  # position lag [m] of the vehicles limited in consecutive steps so far
        self.wished: dict[str, float] = {}  # SUMO's own choice of each vehicle in its last limited step
        self.limited_steps = 0  # vehicle-steps in which the limit changed SUMO's choice
        self.max_lag_m = 0.0
        self.closed = False

    # -- reading --------------------------------------------------------------------------------------------------
    def time(self) -> float:
        return float(self.api.simulation.getTime())

    def read(self) -> Fleet:
        """The fleet now (newly departed vehicles subscribed first)."""
        veh = self.api.vehicle
        for vid in self.api.simulation.getDepartedIDList():
            veh.subscribe(vid, self._vars)
            if vid.startswith("cav."):
                self.equipped.add(vid)
                veh.setLaneChangeMode(vid, 0)  # SUMO's LC2013 only wishes; the shield executes (equipped.py)
        res = veh.getAllSubscriptionResults()
        pos_k, v_k, a_k, road_k, lat_k = self._vars
        # one pass over SUMO's results: (x, y, v, a, on the ramp, lateral speed) per vehicle
        table = np.array([(*r[pos_k], r[v_k], r[a_k], r[road_k] == "ramp", r[lat_k]) for r in res.values()],
                         float).reshape(-1, 6)  # fmt: skip
        on = table[:, 2] >= 0.0  # SUMO's -2^30: not on the road this step
        ids = tuple(i for i, k in zip(res, on.tolist(), strict=True) if k)
        table = table[on]
        pos, v, a, on_ramp, vy = table[:, :2], table[:, 2].copy(), table[:, 3].copy(), table[:, 4] > 0, table[:, 5]
        self._apply_floors(ids, v, a)
        self._v_now = dict(zip(ids, v.tolist(), strict=True))
        x = front_to_centre(pos[:, 0], self.params.vehicle_length)
        lane = np.where(on_ramp, -1, dem.lane_of(pos[:, 1]))
        equipped = np.array([i in self.equipped for i in ids], bool)
        return Fleet(ids, x, pos[:, 1].copy(), v, a, lane, equipped, vy)

    def collisions(self) -> list[dict]:
        """SUMO's own collision list for the last step."""
        t = self.time()
        return [{"t": t, "collider": c.collider, "victim": c.victim, "type": c.type, "lane": c.lane,
                 "pos": float(c.pos), "collider_speed": float(c.colliderSpeed), "victim_speed": float(c.victimSpeed)}
                for c in self.api.simulation.getCollisions()]  # fmt: skip

    def wishes(self, vids) -> np.ndarray:
        """SUMO's LC2013 wish of each vehicle (``+1`` left, ``−1`` right, ``0`` none), from
        ``vehicle.getLaneChangeState``: the model's request (``LCA_LEFT``/``LCA_RIGHT``) for a strategic, cooperative,
        speed-gain or keep-right reason, whether or not SUMO itself would find the gap (the shield decides that)."""
        tc, veh = self.api.constants, self.api.vehicle
        reasons = tc.LCA_STRATEGIC | tc.LCA_COOPERATIVE | tc.LCA_SPEEDGAIN | tc.LCA_KEEPRIGHT
        out = np.zeros(len(vids), np.int64)
        for k, vid in enumerate(vids):
            for direction, bit in ((1, tc.LCA_LEFT), (-1, tc.LCA_RIGHT)):
                state = veh.getLaneChangeState(vid, direction)[0]
                if state & bit and state & reasons and not state & (1 << 30):  # 1 << 30: no lane that way
                    out[k] = direction
                    break
        return out

    # -- commanding -----------------------------------------------------------------------------------------------
    def take(self, vid: str) -> None:
        """Python drives ``vid`` from now on (speed mode 0; placed every period by :meth:`place`)."""
        self.taken.add(vid)
        self.api.vehicle.setSpeedMode(vid, SPEED_MODE_OURS)

    def release(self, vid: str) -> None:
        """Back to SUMO's car following (its speed command cleared)."""
        self.taken.discard(vid)
        self.api.vehicle.setSpeedMode(vid, SPEED_MODE_SUMO)
        self.api.vehicle.setSpeed(vid, -1.0)

    def place(self, vids, x_centre, y_road, speed) -> None:
        """Put vehicles at exact centre positions (any lateral offset) and speeds for the next step (``moveToXY``
        with ``keepRoute=2``: the body stays aligned with the road, as the shield's point-mass model assumes)."""
        front = centre_to_front(np.asarray(x_centre, float), self.params.vehicle_length)
        veh = self.api.vehicle
        for vid, fx, y, v in zip(vids, front.tolist(), np.asarray(y_road, float).tolist(),
                                 np.asarray(speed, float).tolist(), strict=True):  # fmt: skip
            veh.moveToXY(vid, "", -1, fx, y, angle=90.0, keepRoute=2)
            veh.setSpeed(vid, max(v, 0.0))

    def limit_braking(self, vids, decel_mps2) -> None:
        """Connected leaders honour their promises: in the next step each of ``vids`` brakes at most at its
        ``decel_mps2`` [m/s²] — its speed after the step is ``max(v_sumo, v − decel·dt)``, ``v_sumo`` SUMO's own
        choice. SUMO's ``decel`` keeps the human value, so Krauss plans as before; only the executed braking is
        limited. Only for the next step: a vehicle not named in the next call is SUMO's alone.

        SUMO has no speed-floor command (``setSpeed`` replaces SUMO's choice, and while it is active SUMO's own
        choice cannot be read back: ``getSpeedWithoutTraCI`` returns the command), so the limit acts after the
        step (:meth:`read`): where SUMO braked harder, the speed is lifted to ``v − decel·dt``
        (``setPreviousSpeed``, which the next step starts from). SUMO has already moved the vehicle with its own
        choice, so its position trails the limited motion by ``(a_sumo − decel)·dt²/2`` per limited step (3.75 cm
        for 8 vs 0.5 m/s²); :attr:`max_lag_m` is the largest such lag summed over consecutive limited steps."""
        dt = self.params.dt
        floors = {}
        for vid, d in zip(vids, np.asarray(decel_mps2, float).tolist(), strict=True):
            v = self._v_now.get(vid)
            if v is not None and v - d * dt > 0.0 and vid not in self.taken:
                floors[vid] = (v - d * dt, d)
        self._floors = floors

    def _apply_floors(self, ids, v, a) -> None:
        """After a step: each limited vehicle's speed ``max(v_sumo, floor)`` (:meth:`limit_braking`), in SUMO
        (``setPreviousSpeed``) and in this read's arrays (the subscriptions were taken before the correction)."""
        floors, self._floors = self._floors, {}
        veh, dt = self.api.vehicle, self.params.dt
        lag = {}
        for k, vid in enumerate(ids):
            if vid in floors and v[k] < floors[vid][0]:
                floor, d = floors[vid]
                self.wished[vid] = float(v[k])
                lag[vid] = self._lag.get(vid, 0.0) + 0.5 * (floor - v[k]) * dt
                self.max_lag_m = max(self.max_lag_m, lag[vid])
                self.limited_steps += 1
                veh.setPreviousSpeed(vid, floor, -d)
                v[k], a[k] = floor, -d
        self._lag = lag

    def step(self) -> None:
        self.api.simulationStep()

    def arrived(self) -> list[str]:
        return list(self.api.simulation.getArrivedIDList())

    def close(self) -> None:
        if not self.closed:
            try:
                self.api.close()
            finally:
                self.closed = True

    def cleanup(self) -> None:
        self._tmp.cleanup()

    def __enter__(self) -> TrafficWorld:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
        self.cleanup()
