"""The shield in SUMO (libsumo; extra ``sumo``): lane changes on a shipped straight two-lane road, SUMO's own
collision list as the referee.

    from safelane.integrations.sumo import SumoRunner, sumo_scenarios
    with SumoRunner() as runner:                      # one per process: libsumo is a process-wide singleton
        table = runner.run_many(sumo_scenarios(n_leaders=3, decel=6.0, samples=50, seed=0), shielded=True)

Each episode (:meth:`SumoRunner.run`) reloads SUMO (step 0.1 s = ``Params.dt``, ballistic integration, collision
action ``warn`` with min-gap factor 0 — physical contact counts —, the sublane model on) with a route file holding
the scenario's vehicles at their exact initial states, then every period:

1. reads the vehicles **per lane** from SUMO (front bumpers → centres): in the target lane F (the nearest behind the
   ego) and ``L1, L2, …`` (ahead, nearest first); in the ego's own lane ``L0`` (the nearest ahead,
   :func:`own_lane_leaders`);
2. builds the :class:`~safelane.shield.Situation` from :mod:`safelane.v2x` messages of the connected vehicles
   (emulated with loss and latency, :class:`~.sumo_traffic.V2XLink`) and sensed states of the others — the chain
   stops at the first non-connected or stale leader ``L(N+1)``;
3. asks the nominal policy (default: :func:`default_policy`, the built-in simulator's nominal planner — the
   expert, :data:`DEFAULT_NOMINAL`, as ``safelane sumo`` runs it; ``nominal=`` takes another name or a model file;
   ``policy=reckless`` always merges at full authority, the campaign's stress test) and the
   :class:`~safelane.shield.Shield` (or, unshielded, ``ShieldConfig(enabled=False)``: the proposal passes, and the
   ego follows L1 responsibly once across — the built-in simulator's ``supervised=False``);
4. moves the ego as an exact point mass (constant accelerations over the period, the held plan's exact motion when
   aborting; ``moveToXY`` plus speed) and the other vehicles by speed commands (:mod:`.sumo_traffic`: the paper's
   models or SUMO's drivers; ``L(N+1)``'s and ``L0``'s braking injected);
5. steps SUMO and reads its collision list (and our geometric cross-check, :func:`.sumo_world.overlaps`).
"""

from __future__ import annotations

import dataclasses
import itertools
import time

import numpy as np

from .. import v2x
from .._motion import advance
from ..baselines.rss import RssParams
from ..params import Params
from ..shield import ABORT, HESITATE, PROCEED, Shield, ShieldConfig, Situation
from ..shield.command import Command, InFlight
from .sumo_episode import EpisodeResult, StateLog, SumoScenario, scenarios_from_batch, sumo_scenarios
from .sumo_traffic import TRAFFIC_MODES, TargetLaneTraffic, V2XLink, profile_accel
from .sumo_world import SumoWorld, VehicleSpec, libsumo_available, net_file, overlaps

__all__ = [
    "DEFAULT_NOMINAL",
    "TRAFFIC_MODES",
    "EpisodeResult",
    "NominalPolicy",
    "SumoRunner",
    "SumoScenario",
    "default_policy",
    "libsumo_available",
    "net_file",
    "own_lane_leaders",
    "reckless",
    "scenarios_from_batch",
    "sumo_scenarios",
]

ROAD_X0 = 300.0  # the scenario's x = 0 (the ego's start) on the 3 km road
FAR_M = 1e4  # a missing F / leader is replaced by a harmless one this far away


def reckless(situation: Situation, params: Params):
    """The reckless nominal policy: always merge at full authority — ``a_x = a_x_a`` and ``a_y = ±a_y_m`` toward the
    target lane's centre (no damping)."""
    n = len(situation)
    a_y = params.a_y_m * np.sign(params.lane_width - situation.ego_y)
    return np.full(n, params.a_x_a), a_y


def own_lane_leaders(ego_x: float, lane_x, lane_v):
    """``L0`` from the ego's own lane as read from SUMO (centres, sorted): ``((1, 1) x, (1, 1) v)`` — the nearest
    vehicle ahead of the ego's centre, ``+inf`` position (speed 0) where there is none. The one place the own lane
    is filled (``Situation.from_arrays(own_leaders=...)``; ``L0`` not connected: worst case ``a_x_d``)."""
    ahead = np.flatnonzero(np.asarray(lane_x) > ego_x)
    if ahead.size == 0:
        return np.array([[np.inf]]), np.array([[0.0]])
    i = ahead[0]
    return np.array([[float(lane_x[i])]]), np.array([[float(lane_v[i])]])


class NominalPolicy:
    """A nominal planner of the built-in simulator (:class:`safelane.planners.NominalPlanner`, e.g.
    ``ExpertPlanner()``) as a SUMO policy: the :class:`~safelane.planners.Observation` is built as
    ``safelane.sim.step.ClosedLoop.observe`` builds it — F and L1 as read from SUMO (the nearest behind / ahead in
    the target lane), ``l1_plan`` L1's last commanded acceleration held over ``l1_plan_steps`` periods where the
    variant uses the chain and L1 is connected, zeros otherwise."""

    def __init__(self, planner, variant: str = "CV_all", l1_plan_steps: int = 10):
        from ..planners.variants import get_variant

        self.planner, self.l1_plan_steps = planner, int(l1_plan_steps)
        self.uses_chain = bool(get_variant(variant).uses_chain)
        self.__name__ = getattr(planner, "__name__", type(planner).__name__)

    def observation(self, situation: Situation, l1_acc: float, l1_connected: bool, f_connected: bool,
                    completed: bool, scenario_id: int):  # fmt: skip
        from ..planners.base import Observation

        plan = l1_acc if (self.uses_chain and l1_connected) else 0.0
        return Observation(
            p_x=situation.ego_x, p_y=situation.ego_y, v_x=situation.ego_vx, v_y=situation.ego_vy,
            p_x_l=situation.chain_x[:, 0], v_x_l=situation.chain_v[:, 0], p_x_f=situation.f_x, v_x_f=situation.f_v,
            l1_plan=np.full((1, self.l1_plan_steps), plan), l1_connected=np.array([l1_connected]),
            f_connected=np.array([f_connected]), completed=np.array([completed]), t=situation.t,
            scenario_id=np.array([scenario_id]),
        )  # fmt: skip


#: The nominal planner of a SUMO run unless told otherwise — :class:`SumoRunner` and ``safelane sumo``
#: (:func:`~.sumo_cells.run_episodes`) alike, through :func:`default_policy`: the built-in simulator's default.
DEFAULT_NOMINAL = "expert"


def default_policy(variant: str = "CV_all", nominal=None) -> NominalPolicy:
    """The nominal policy of :class:`SumoRunner` and ``safelane sumo`` (the one place both take it from):
    ``nominal`` — a planner object, a registered name or the path of a ``.npz``/``.onnx`` model
    (:func:`~safelane.planners.registry.load_nominal`); default :data:`DEFAULT_NOMINAL` — observed as the built-in
    simulator observes it (``SimConfig().l1_plan_steps``) under the planner variant ``variant``."""
    from ..sim import SimConfig
    from ..sim.inputs import as_nominal

    planner = as_nominal(DEFAULT_NOMINAL if nominal is None else nominal)
    return NominalPolicy(planner, variant, SimConfig().l1_plan_steps)


class SumoRunner:
    """Runs episodes in one SUMO simulation (one per process: libsumo is a singleton; use processes for parallel
    episodes). ``traci=True`` runs SUMO as a separate process through TraCI (needs a SUMO binary), ``gui=True``
    in sumo-gui; ``fcd``: SUMO's floating-car-data output file (the last episode's). ``world``: share an open
    :class:`~.sumo_world.SumoWorld` between runners of other settings (it stays open when this runner closes).

    The nominal policy: ``policy`` (``policy(situation, params) -> (a_x, a_y)``, e.g. :func:`reckless`, or a
    :class:`NominalPolicy`) if given, else :func:`default_policy` of ``variant`` and ``nominal`` (a name such as
    ``"mlp"``, a model file, or a planner; default the expert) — the planner ``safelane sumo`` runs, so the same
    cell and seed give the same numbers here and there."""

    def __init__(self, params: Params | None = None, *, variant: str = "CV_all", config: ShieldConfig | None = None,
                 traffic: str = "paper", v2x_loss: float = 0.0, v2x_latency_periods: int = 0,
                 v2x_max_age_s: float = v2x.MAX_AGE_S, horizon_s: float = 10.0, policy=None, nominal=None,
                 stop_on_collision: bool = True, traci: bool = False, gui: bool = False, fcd: str | None = None,
                 seed: int = 0, world: SumoWorld | None = None, sensing=None):  # fmt: skip
        if traffic not in TRAFFIC_MODES:
            raise ValueError(f"traffic must be one of {TRAFFIC_MODES}; got {traffic!r}")
        if policy is not None and nominal is not None:
            raise ValueError("give either policy or nominal, not both")
        self.params = params or Params()
        self.variant, self.config = variant, config or ShieldConfig()
        policy = default_policy(variant, nominal) if policy is None else policy
        self.traffic, self.policy, self.horizon_s = traffic, policy, float(horizon_s)
        self.v2x = dict(loss=float(v2x_loss), latency_periods=int(v2x_latency_periods), max_age_s=float(v2x_max_age_s))
        self.stop_on_collision, self.seed = stop_on_collision, int(seed)
        # Real roads: error bounds the shield takes the worst case over (a SensingBounds, or None: SUMO's exact states)
        # and the actuation delay of ``config`` (the ego executes each command that much later).
        self.sensing = sensing
        self.delay_periods = round(self.config.actuation_delay_s / self.params.dt)
        self._owns_world = world is None
        self.world = SumoWorld(self.params, traci=traci, gui=gui, fcd=fcd, seed=seed) if world is None else world

    def close(self) -> None:
        if self._owns_world:
            self.world.close()

    def __enter__(self) -> SumoRunner:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def settings(self) -> dict:
        """The settings as SUMO reports them, read back when the first episode started SUMO: available from the
        first :meth:`run` on, also after the runner is closed (``RuntimeError`` saying so before)."""
        return self.world.settings()

    def run_many(self, scenarios, *, shielded: bool = True):
        """A ``pandas.DataFrame`` with one :meth:`EpisodeResult.row` per scenario."""
        import pandas as pd

        return pd.DataFrame([self.run(sc, shielded=shielded).row() for sc in scenarios])

    def run(self, sc: SumoScenario, *, shielded: bool = True) -> EpisodeResult:
        prm, world = self.params, self.world
        dt = prm.dt
        t_wall = time.perf_counter()
        k_lead = len(sc.leaders_x)
        slot_ids = ["F", *(f"L{i}" for i in range(1, k_lead + 1))]
        traffic = TargetLaneTraffic(
            params=prm, mode=self.traffic, n_connected=sc.n_connected, promise_decel=sc.promise_decel,
            promise_accel=sc.promise_accel, f_aggressive=sc.f_aggressive, decel_last=sc.decel_last,
            brake_start_s=sc.brake_start_s, v_desired=np.array([sc.f_v, *sc.leaders_v]), gap0=sc.ego_x - sc.f_x,
        )  # fmt: skip
        connected = {slot_ids[i] for i in range(1, sc.n_connected + 1)} | ({"F"} if sc.f_connected else set())
        vehicles = [VehicleSpec("ego", 0, ROAD_X0 + sc.ego_x, sc.ego_v), VehicleSpec("F", 1, ROAD_X0 + sc.f_x, sc.f_v)]
        vehicles += [VehicleSpec(slot_ids[i + 1], 1, ROAD_X0 + x, v)
                     for i, (x, v) in enumerate(zip(sc.leaders_x, sc.leaders_v, strict=True))]  # fmt: skip
        if sc.own_x is not None:
            vehicles.append(VehicleSpec("L0", 0, ROAD_X0 + sc.own_x, sc.own_v))
        world.load(vehicles, frozenset(slot_ids[i] for i in traffic.sumo_driven))
        # The blame rule's record (safelane.blame), with RSS at this world's limits (rho one period).
        self.log = StateLog([veh.vid for veh in vehicles], prm.vehicle_length, prm.vehicle_width,
                            RssParams.matched(prm))  # fmt: skip
        origin, sign = world.lane_y[0], (1.0 if world.lane_y[1] > world.lane_y[0] else -1.0)
        link = V2XLink(prm, seed=self.seed * 1_000_003 + sc.scenario_id, **self.v2x)
        config = self.config if shielded else self.config.model_copy(update={"enabled": False})
        shield = Shield(prm, variant=self.variant, config=config)
        res = EpisodeResult(sc.scenario_id, sc.n_connected, sc.decel_last, sc.own_x is not None, sc.own_decel,
                            self.traffic, shielded, f_aggressive=sc.f_aggressive,
                            f_connected=sc.f_connected)  # fmt: skip

        ex, ey, evx, evy = ROAD_X0 + sc.ego_x, 0.0, sc.ego_v, 0.0  # the ego: road x, shield-frame y (exact state)
        completed = False
        in_flight = None
        if self.delay_periods:  # the commands acting when the episode starts: cruise
            in_flight = InFlight.idle(1, self.delay_periods)
        last_acc = {vid: 0.0 for vid in slot_ids}
        steps = round(self.horizon_s / dt)
        t = 0.0
        for k in range(steps):
            if k:  # accumulated as the shield does (its held plans start at t + dt): k * dt may differ by an ulp
                t = t + dt
            tgt, own = world.lane(1, exclude="ego"), world.lane(0, exclude="ego")
            state = {vid: (x, v) for lane in (tgt, own) for vid, x, v in zip(lane.ids, lane.x, lane.v, strict=True)}
            link.broadcast(k, [self._message(vid, t, *state[vid], last_acc.get(vid, 0.0), sc)
                               for vid in sorted(connected) if vid in state])  # fmt: skip
            link.receive(k)
            situation = self._situation(t, (ex, ey, evx, evy), tgt, own, connected, link)
            if isinstance(self.policy, NominalPolicy):
                l1 = tgt.ids[int(np.searchsorted(tgt.x, ex, side="right"))] if (tgt.x > ex).any() else ""
                obs = self.policy.observation(situation, last_acc.get(l1, 0.0), l1 in connected, sc.f_connected,
                                              completed, sc.scenario_id)  # fmt: skip
                proposal = self.policy.planner(obs, prm)
            else:
                proposal = self.policy(situation, prm)
            if k == 0:
                shield.reset(situation)
                res.initial_safe = bool(shield.state.plan.feasible[0])
            d = shield.step(situation, proposal)
            res.n_proceed += int(d.behaviour[0] == PROCEED)
            res.n_hesitate += int(d.behaviour[0] == HESITATE)
            res.n_abort += int(d.behaviour[0] == ABORT)
            res.n_invalid += int(d.invalid[0])
            rows, _, px, vx, py, vy = d.abort_motion()
            completing = bool(d.completing[0])
            if self.delay_periods:  # the oldest command in flight acts now; this one joins the queue
                acting, in_flight = in_flight.push(Command.of(d))
                ego1 = tuple(np.array([q], float) for q in (ex, ey, evx, evy))
                nx, ny, nv, nvy = acting.carry(*ego1, dt)
                ex, evx, ey, evy = float(nx[0]), float(nv[0]), float(ny[0]), float(nvy[0])
                completing = bool(acting.completing[0])
            elif rows.size:  # the held plan's exact motion over the period
                ex, evx, ey, evy = float(px[0, -1]), float(vx[0, -1]), float(py[0, -1]), float(vy[0, -1])
            else:
                nx, nv = advance(np.float64(ex), np.float64(evx), np.float64(d.a_x[0]), dt)
                ey, evy = ey + evy * dt + 0.5 * d.a_y[0] * dt * dt, evy + d.a_y[0] * dt
                ex, evx = float(nx), float(nv)

            # The others: this period's accelerations from the states at its start.
            xs = np.array([state[vid][0] for vid in slot_ids])
            vs = np.array([state[vid][1] for vid in slot_ids])
            acc = traffic.step(t, xs, vs, situation.ego_x[0], situation.ego_vx[0], completed)
            for i, vid in enumerate(slot_ids):
                if np.isfinite(acc[i]):
                    world.set_speed(vid, vs[i] + acc[i] * dt)
                    last_acc[vid] = float(acc[i])
            if "L0" in state:
                a0 = profile_accel(t, sc.own_brake_start_s, sc.own_decel)
                world.set_speed("L0", state["L0"][1] + a0 * dt)
            if not completed and completing:
                res.completion_time_s = t + dt
            completed = completed or completing
            world.place("ego", ex, origin + sign * ey, evx)
            world.step()
            res.steps = k + 1

            v_new = np.array([world.api.vehicle.getSpeed(vid) for vid in slot_ids])
            for i, vid in enumerate(slot_ids):
                if not np.isfinite(acc[i]):
                    last_acc[vid] = float((v_new[i] - vs[i]) / dt)
            traffic.observe(vs, v_new)
            self._referee(res, t + dt, ey, origin, sign, vehicles, evy)
            if res.collided and self.stop_on_collision:
                break
        res.completed = completed
        state = shield.state
        res.breach = bool(state.breach.any[0])
        res.breach_time_s = float(state.breach.first_s[0])
        res.breach_flags = tuple(bool(f) for f in state.breach.flags[0])
        res.assessed_aggressive = bool(state.belief.aggressive[0])
        res.assessment_time_s = float(state.belief.first_collaborative_s[0])
        res.promise_violations = traffic.violations
        res.v2x_sent, res.v2x_lost = link.sent, link.lost
        res.wall_s = time.perf_counter() - t_wall
        return res

    # -- pieces of a period -------------------------------------------------------------------------------------
    def _message(self, vid, t, x, v, a, sc: SumoScenario) -> v2x.V2XMessage:
        prm = self.params
        intent = None
        if vid == "F":
            intent = "aggressive" if sc.f_aggressive else "collaborative"
        return v2x.V2XMessage(
            vehicle_id=vid, timestamp_s=t, position_m=float(x), speed_mps=float(v),
            accel_mps2=float(np.clip(a, -prm.a_x_d, prm.a_x_a)), promise_decel=sc.promise_decel,
            promise_accel=sc.promise_accel, human_driven=False, intent=intent,
        )  # fmt: skip

    def _situation(self, t, ego, tgt, own, connected, link) -> Situation:
        """The Situation from the lanes as read: F and the chain from messages (fresh) or sensed states."""
        prm = self.params
        ex, ey, evx, evy = ego
        behind = np.flatnonzero(tgt.x <= ex)
        ahead = np.flatnonzero(tgt.x > ex)

        def item(i):
            vid = tgt.ids[i]
            msg = link.message(vid) if vid in connected else None
            if msg is not None:
                return msg
            return v2x.SensedVehicle(vehicle_id=vid, timestamp_s=t, position_m=float(tgt.x[i]),
                                     speed_mps=float(tgt.v[i]))  # fmt: skip

        leaders = [item(i) for i in ahead]
        if not leaders:
            leaders = [v2x.SensedVehicle(vehicle_id="none-ahead", timestamp_s=t, position_m=ex + FAR_M, speed_mps=evx)]
        max_age = self.v2x["max_age_s"]
        chain = v2x.leader_arrays(leaders, t, prm, max_age_s=max_age)
        if behind.size:
            f = item(behind[-1])
        else:
            f = v2x.SensedVehicle(vehicle_id="none-behind", timestamp_s=t, position_m=ex - FAR_M, speed_mps=0.0)
        if isinstance(f, v2x.V2XMessage):
            status = v2x.follower_status(f, t, prm, max_age_s=max_age)
            f_conn, f_coll = status.connected, status.collaborative
            a_f = f.accel_mps2 if f_conn else -prm.a_x_d
        else:
            f_conn = f_coll = False
            a_f = -prm.a_x_d
        fx, fv = v2x.extrapolate(f.position_m, f.speed_mps, a_f, max(t - f.timestamp_s, 0.0))
        situation = Situation.from_arrays(
            t=t, ego=(ex, ey, evx, evy), follower=(fx, fv), leaders=(chain.p[None, :], chain.v[None, :]),
            n_connected=chain.n_connected, promise_decel=chain.promise_decel[None, :],
            human_driven=chain.human_driven[None, :], f_connected=f_conn, f_collaborative=f_coll, params=prm,
            own_leaders=own_lane_leaders(ex, own.x, own.v), own_n_connected=0, sensing=self.sensing,
        )  # fmt: skip
        stale = bool(chain.stale_ids) or (isinstance(f, v2x.V2XMessage) and not f_conn)
        return dataclasses.replace(situation, v2x_stale=np.array([stale]))

    def _referee(self, res: EpisodeResult, t, ey, origin, sign, vehicles, evy=0.0) -> None:
        prm = self.params
        phase = "original lane" if ey <= prm.y_safe else ("straddling" if ey < prm.lane_width - prm.y_safe
                                                          else "target lane")  # fmt: skip
        ids = [veh.vid for veh in vehicles]
        pos = [self.world.position(vid) for vid in ids]
        x, y = [p[0] for p in pos], [p[1] for p in pos]
        speed = [self.world.api.vehicle.getSpeed(vid) for vid in ids]
        self.log.record(t, x, y, speed, [sign * evy if vid == "ego" else np.nan for vid in ids])
        new = [{**c, "t": round(t, 3), "phase": phase, "ego_y": ey} for c in self.world.collisions()]
        self.log.classify(new)
        res.collided = res.collided or bool(new)
        res.collisions.extend(new)
        pairs = [(0, j) for j in range(1, len(ids))]
        same_lane = sorted(range(1, len(ids)), key=lambda i: (vehicles[i].lane, x[i]))
        pairs += [(i, j) for i, j in itertools.pairwise(same_lane) if vehicles[i].lane == vehicles[j].lane]
        for i, j, gx, gy in overlaps(x, y, prm, pairs):
            res.overlaps.append({"a": ids[i], "b": ids[j], "t": round(t, 3), "gap_x": gx, "gap_y": gy, "phase": phase})
