"""The shield in highway-env (extra ``highway``): :class:`SafeLaneShield`, a Gymnasium wrapper.

``SafeLaneShield(env)`` takes physical continuous actions ``(a_x, a_y)`` [m/s²] (``a_y > 0`` toward the target
lane), reads the vehicles from ``env.unwrapped.road`` (not from the observation), finds F and L1 in the target lane
(and L0 ahead of the ego in its own lane) and every other vehicle as the Situation's ``others`` (which the shield
folds into those roles where one can enter the ego's path: :mod:`safelane.shield.world`), builds a
:class:`~safelane.shield.Situation` (a
:class:`~safelane.shield.LaneFrame` maps highway-env's ``y``-to-the-right, lane-0-leftmost frame), asks
:meth:`Shield.step <safelane.shield.Shield.step>` and moves the ego — replaced at every reset by a
:class:`~.highway_vehicles.PointMassVehicle`, an exact point mass — by the decision. highway-env's own collision
check (``info["crashed"]``) is the referee. See docs/integrations.md.

Importing this module imports gymnasium and highway-env (``pip install "safelane[highway]"``) and registers the
lane-change scene ``safelane/HighwayScene-v0`` (:mod:`.highway_scene`).
"""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np

INSTALL_HINT = 'pip install "safelane[highway]"  (gymnasium >= 1.0, highway-env >= 1.12)'

try:
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers highway-v0 & co.)
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(f"safelane.integrations.highway needs gymnasium and highway-env: {INSTALL_HINT}") from exc

from ..baselines.rss import RssParams  # noqa: E402
from ..blame import PairTracker  # noqa: E402
from ..params import Params  # noqa: E402
from ..shield import ABORT, COMPLETED, HESITATE, PROCEED, LaneFrame, Shield, ShieldConfig, Situation  # noqa: E402
from ..shield.command import Command, InFlight  # noqa: E402
from ..tolerances import TIME_TOL_S  # noqa: E402
from ..v2x import MAX_AGE_S, SensedVehicle, V2XMessage, leader_arrays  # noqa: E402
from .highway_road import (  # noqa: E402
    blame_tracks,
    check_frequencies,
    check_road,
    classify_crash,
    crash_partner,
    highway_params,
    longitudinal,
    own_lane_leaders,
    road_others,
)
from .highway_vehicles import (  # noqa: E402
    NoCutInIDMVehicle,
    PointMassVehicle,
    PromiseIDMVehicle,
    SuddenBrakeVehicle,
    cuts_in,
)

SCENE_ENV_ID = "safelane/HighwayScene-v0"
#: What a highway-env environment needs for the wrapper: the shield's period at both frequencies, continuous actions
#: (the wrapper drives the ego itself; any action type works, this one keeps the host's action space a box).
HIGHWAY_CONFIG = {"simulation_frequency": 10, "policy_frequency": 10, "action": {"type": "ContinuousAction"}}
#: highway-env traffic inside the shield's assumptions about the lanes: while the ego changes lanes, MOBIL starts no
#: lane change into the ego's target or original lane beside the ego or between it and its nearest leader there
#: (:class:`~.highway_vehicles.NoCutInIDMVehicle`). Add ``lanes_count: 2`` for the paper's two lanes.
NO_CUT_IN_CONFIG = {"other_vehicles_type": "safelane.integrations.highway_vehicles.NoCutInIDMVehicle"}
BEHAVIOUR = {PROCEED: "proceed", HESITATE: "hesitate", ABORT: "abort", COMPLETED: "completed"}
FAR_M = 1000.0  # where a missing F or L1 is put (behind / ahead of the ego)
#: The Situation takes the ego's own-lane leaders (docs/real_roads.md) where its ``from_arrays`` has ``own_leaders``.
OWN_LANE_SUPPORTED = "own_leaders" in inspect.signature(Situation.from_arrays).parameters

__all__ = [
    "HIGHWAY_CONFIG",
    "INSTALL_HINT",
    "NO_CUT_IN_CONFIG",
    "SCENE_ENV_ID",
    "NoCutInIDMVehicle",
    "PointMassVehicle",
    "PromiseIDMVehicle",
    "SafeLaneShield",
    "SuddenBrakeVehicle",
    "check_frequencies",
    "classify_crash",
    "highway_params",
    "own_lane_leaders",
    "register_highway_envs",
]


def register_highway_envs() -> None:
    """Register ``safelane/HighwayScene-v0`` (idempotent)."""
    if SCENE_ENV_ID not in gym.registry:
        gym.register(id=SCENE_ENV_ID, entry_point="safelane.integrations.highway_scene:LaneChangeScene")


class SafeLaneShield(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """The shield between a policy and a highway-env environment (see the module docstring).

    Args:
        env: a highway-env environment on a straight road, at 10 Hz simulation and 10 Hz policy (else a
            ``ValueError`` naming ``simulation_frequency`` / ``policy_frequency``; see :data:`HIGHWAY_CONFIG`).
        shield: ``False`` executes the (clipped) action unfiltered — the same ego, frame and info keys.
        variant: the shield's information use; default ``"No_agg_assess"`` (L1 at ``a_x_d``, F always assumed
            aggressive: highway-env's traffic is not connected, and IDM's F is no responsible yielder braking at
            ``a_x_d``), ``"CV_all"`` where ``connected`` vehicles are marked.
        params: default :func:`highway_params`.
        config: the :class:`~safelane.shield.ShieldConfig`.
        target: ``"left"`` (lane id − 1), ``"right"`` or ``"auto"`` (left unless the ego is in lane 0).
        connected: treat vehicles with a true ``safelane_connected`` attribute as connected (their promise in
            ``safelane_promise`` [m/s²], default ``promise``): each period every connected vehicle of the chain (and
            F) broadcasts a :class:`~safelane.v2x.V2XMessage` — its exact state, its acceleration of the last
            period, its promise, the timestamp — and the chain is built from the received ones by
            :func:`safelane.v2x.leader_arrays` (the first vehicle that is not connected, or whose latest message is
            stale, becomes ``L(N+1)``). The scene's ``config={"connected": True}`` marks F and L1..LN and holds the
            leaders to their promise (:class:`~.highway_vehicles.PromiseIDMVehicle`).
        v2x_loss, v2x_seed: each message is lost independently with probability ``v2x_loss`` (default 0: an ideal
            link), drawn from ``numpy.random.default_rng`` seeded by ``v2x_seed`` and the reset's seed; the latest
            received message then stands in, extrapolated, until it is older than ``safelane.v2x.MAX_AGE_S``.
        own_leaders: how many own-lane leaders to read (used once the Situation takes them; docs/real_roads.md).
        others: pass every other vehicle on the road (not F, the chain or the own-lane leaders) as the Situation's
            ``others`` (:mod:`safelane.shield.world`: a vehicle that straddles, or whose RSS lateral worst case reaches
            the target or the ego's lane, takes a role), so the shield covers stock highway-v0 traffic whose MOBIL
            moves vehicles into those lanes. highway-env's vehicles announce nothing over V2X, so every one counts as
            non-connected there. ``False``: the paper's world (only F, the chain and L0), the wrapper before the
            world model.

    Actions: ``Box([-a_x_d, -a_y_m], [a_x_a, a_y_m])``; ``a_y > 0`` points to the target lane. ``info`` adds
    ``shield`` (``proceed``/``hesitate``/``abort``/``completed``, ``off`` without the shield), ``intervened``,
    ``nominal_action``, ``executed_action`` (``Δv/dt`` over the period, shield frame), ``reason``, ``cost`` (1.0 in the
    period the ego crashes or first comes closer than ``p_m`` to F or L1 while out of its lane, at period ends),
    ``completed`` (the ego's centre has crossed into the target lane), ``cut_in`` (in this episode, while the ego
    was not yet wholly in the target lane, another vehicle began moving into the target lane or the ego's original
    lane beside the ego or between it and its nearest leader there — :func:`~.highway_vehicles.cuts_in`: outside the
    shield's assumptions) and, on a crash, ``crash`` (:func:`classify_crash`); highway-env's ``crashed`` is kept.
    ``crash_blame`` (every step): who is responsible for the ego's crash — ``"ego"``, ``"other"``, ``"both"``, or
    ``None`` without a crash — by :mod:`safelane.blame`'s rule on the states of the ego and its crash partner (the
    nearest other vehicle highway-env flags ``crashed``), followed every period since the reset; ``crash`` then adds
    the rule's ``blame_clause`` and ``blame_t``. ``blame_rss``: the rule's RSS parameters (default
    ``RssParams.matched(params)``: this world's limits, ρ one period).
    The manoeuvre is published as ``road.safelane_manoeuvre`` for :class:`~.highway_vehicles.NoCutInIDMVehicle`
    (:data:`NO_CUT_IN_CONFIG`).
    """

    def __init__(self, env, shield: bool = True, variant: str | None = None, params: Params | None = None,
                 config: ShieldConfig | None = None, target: str = "auto", connected: bool = False,
                 promise: float = 0.5, own_leaders: int = 1, sensing=None, v2x_loss: float = 0.0,
                 v2x_seed: int | None = None, blame_rss: RssParams | None = None, others: bool = True):  # fmt: skip
        gym.utils.RecordConstructorArgs.__init__(self, shield=shield, variant=variant, params=params, config=config,
                                                 target=target, connected=connected, promise=promise,
                                                 own_leaders=own_leaders, sensing=sensing, v2x_loss=v2x_loss,
                                                 v2x_seed=v2x_seed, blame_rss=blame_rss, others=others)  # fmt: skip
        gym.Wrapper.__init__(self, env)
        if target not in ("left", "right", "auto"):
            raise ValueError(f"target must be 'left', 'right' or 'auto'; got {target!r}")
        self.params = params or highway_params()
        check_frequencies(env, self.params)
        prm = self.params
        if prm.p_m < PointMassVehicle.LENGTH or prm.vehicle_width < PointMassVehicle.WIDTH:
            raise ValueError(f"Params must cover highway-env's {PointMassVehicle.LENGTH} x {PointMassVehicle.WIDTH} m "
                             f"vehicles (p_m >= length, vehicle_width >= width): use highway_params()")  # fmt: skip
        self.shield_on = bool(shield)
        self.variant = variant or ("CV_all" if connected else "No_agg_assess")
        self.shield = Shield(prm, variant=self.variant, config=config)
        # Real roads: error bounds the shield takes the worst case over (a SensingBounds; None: highway-env's exact
        # states), and the actuation delay of the config, which the ego's actuator then applies.
        self.sensing = sensing
        self.delay_periods = round(self.shield.config.actuation_delay_s / prm.dt)
        self.in_flight = None
        self.target = target
        self.connected = bool(connected)
        self.promise = float(promise)
        if not 0.0 <= float(v2x_loss) <= 1.0:
            raise ValueError(f"v2x_loss must lie in [0, 1]; got {v2x_loss!r}")
        self.v2x_loss, self.v2x_seed = float(v2x_loss), v2x_seed
        self.rng = np.random.default_rng(v2x_seed)
        self.inbox: dict = {}  # the latest message received from each connected vehicle (id(vehicle) -> message)
        self.chain_v2x = None  # the last LeaderChain (safelane.v2x.leader_arrays), with connected=True
        self.n_own = int(own_leaders)
        self.with_others = bool(others)
        self.blame_rss = blame_rss or RssParams.matched(prm)
        self.blame = PairTracker(self.blame_rss)
        self.crash_blame: tuple | None = None  # (responsible, clause, blame time) of the ego's first crash
        self.action_space = gym.spaces.Box(np.array([-prm.a_x_d, -prm.a_y_m], np.float32),
                                           np.array([prm.a_x_a, prm.a_y_m], np.float32), dtype=np.float32)  # fmt: skip
        self.ego: PointMassVehicle | None = None
        self.frame = LaneFrame()
        self.roles: dict = {}

    # --- the host's state ---------------------------------------------------------------------------------------
    def _host_action(self):
        space = self.env.unwrapped.action_space
        if isinstance(space, gym.spaces.Discrete):
            return 1  # DiscreteMetaAction's IDLE (the point-mass ego ignores it)
        return np.zeros(space.shape, space.dtype)

    def _chain(self, road):
        """L1, L2, … in the target lane: L1 and, while connected, the next ones (the last one non-connected)."""
        chain, current = [], self.ego
        while True:
            front, _ = road.neighbour_vehicles(current, self.target_lane)
            if front is None:
                break
            chain.append(front)
            if not (self.connected and getattr(front, "safelane_connected", False)) or len(chain) > 50:
                break
            current = front
        return chain

    def _message(self, vehicle):
        """What ``vehicle`` broadcasts now: its exact state, last acceleration and promise (a V2XMessage)."""
        prm = self.params
        x, v = longitudinal(vehicle)
        accel = float(getattr(vehicle, "action", {}).get("acceleration", 0.0))
        promise = min(max(float(getattr(vehicle, "safelane_promise", self.promise)), 0.0), prm.a_x_d)
        return V2XMessage(vehicle_id=str(id(vehicle)), timestamp_s=self.t, position_m=x, speed_mps=v,
                          accel_mps2=accel if np.isfinite(accel) else 0.0, promise_decel=promise,
                          promise_accel=prm.a_x_a, human_driven=False)  # fmt: skip

    def _received(self, vehicle):
        """The latest message received from a connected ``vehicle`` (this period's unless lost), else what the ego
        senses of it now (a SensedVehicle)."""
        if self.v2x_loss <= 0.0 or self.rng.random() >= self.v2x_loss:
            self.inbox[id(vehicle)] = self._message(vehicle)
        message = self.inbox.get(id(vehicle))
        if message is not None:
            return message
        x, v = longitudinal(vehicle)
        return SensedVehicle(vehicle_id=str(id(vehicle)), timestamp_s=self.t, position_m=x, speed_mps=v)

    def _v2x_leaders(self, chain):
        """The chain ``L1, L2, …`` as the ego receives it (:func:`safelane.v2x.leader_arrays`): ``(x, v, promise,
        n, stale)``."""
        leaders = []
        for vehicle in chain:
            if getattr(vehicle, "safelane_connected", False):
                leaders.append(self._received(vehicle))
            else:
                x, v = longitudinal(vehicle)
                leaders.append(SensedVehicle(vehicle_id=str(id(vehicle)), timestamp_s=self.t, position_m=x,
                                             speed_mps=v))  # fmt: skip
        got = leader_arrays(leaders, self.t, self.params)
        self.chain_v2x = got
        return got.p, got.v, got.promise_decel, got.n_connected, bool(got.stale_ids)

    def situation(self) -> Situation:
        """What the ego knows now, read from the road (and, with ``connected``, from the V2X messages)."""
        ego, road, prm = self.ego, self.env.unwrapped.road, self.params
        ex = float(ego.position[0])
        _, f = road.neighbour_vehicles(ego, self.target_lane)
        chain = self._chain(road)
        roles = {}
        f_connected, stale = False, False
        if f is not None:
            fx, fv = longitudinal(f)
            roles[id(f)] = "F"
            if self.connected and getattr(f, "safelane_connected", False):
                # F's message: fresh or not, it declares no intent (IDM yields to no one), so F stays aggressive
                msg = self._received(f)
                f_connected = isinstance(msg, V2XMessage) and self.t - msg.timestamp_s <= MAX_AGE_S + TIME_TOL_S
                stale = stale or (isinstance(msg, V2XMessage) and not f_connected)
        else:
            fx, fv = ex - FAR_M, 0.0
        roles.update({id(v): f"L{i + 1}" for i, v in enumerate(chain)})
        if chain and self.connected:
            lx, lv, promise, n, chain_stale = self._v2x_leaders(chain)
            stale = stale or chain_stale
        elif chain:
            lx, lv = np.array([longitudinal(v) for v in chain[:1]]).T
            n, promise = 0, np.zeros(0)
        else:
            lx, lv = np.array([ex + FAR_M]), np.array([ego.speed])
            n, promise = 0, np.zeros(0)
        ox, ov, own = own_lane_leaders(road, ego, self.original_lane, self.n_own)
        roles.update({id(v): f"L0{'' if i == 0 else f'+{i}'}" for i, v in enumerate(own)})
        scene_roles = getattr(self.env.unwrapped, "scene", {}).get("roles", {})
        self.roles = {**scene_roles, **roles}
        kwargs = {}
        if OWN_LANE_SUPPORTED:
            kwargs = {"own_leaders": (ox[None, :], ov[None, :]), "own_n_connected": 0, "own_promise": self.promise}
        if self.with_others:
            kwargs["others"] = road_others(road, {id(ego), *roles}, self.frame)
        situation = Situation.from_arrays(
            t=self.t, ego=(ex, ego.position[1], ego.speed, ego.lateral_speed), follower=(fx, fv),
            leaders=(lx[None, :], lv[None, :]), n_connected=n, promise_decel=promise[None, :] if promise.size else
            np.zeros((1, len(lx) - 1)), f_connected=f_connected, frame=self.frame, params=prm,
            sensing=self.sensing, **kwargs,
        )  # fmt: skip
        if self.connected:
            situation = dataclasses.replace(situation, v2x_stale=np.array([stale]))
        return situation

    def reset_blame(self) -> None:
        """Start the blame rule afresh from the road as it is now (reset does; a test that rebuilds the scene after
        reset calls it too)."""
        self.blame, self.crash_blame = PairTracker(self.blame_rss), None
        self._observe_blame()

    def _observe_blame(self) -> None:
        """One sample of the ego against every other road vehicle for the blame rule (:mod:`safelane.blame`)."""
        others = [v for v in self.env.unwrapped.road.vehicles if v is not self.ego]
        ego, tracks = blame_tracks(self.ego, others)
        self.blame.observe(self.t, ego, [id(v) for v in others], tracks)

    # --- Gymnasium ------------------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        u = self.env.unwrapped
        self.inbox, self.chain_v2x = {}, None
        if seed is not None:
            self.rng = np.random.default_rng([seed] if self.v2x_seed is None else [self.v2x_seed, seed])
        check_frequencies(self.env, self.params)
        check_road(u.road, self.params)
        old = u.vehicle
        self.ego = PointMassVehicle.replacing(old)
        u.road.vehicles[u.road.vehicles.index(old)] = self.ego
        u.controlled_vehicles[0] = self.ego
        lane = self.ego.lane_index
        lanes = u.road.network.graph[lane[0]][lane[1]]
        side = self.target if self.target != "auto" else ("left" if lane[2] > 0 else "right")
        tid = lane[2] - 1 if side == "left" else lane[2] + 1
        if not 0 <= tid < len(lanes):
            raise ValueError(f"the ego starts in lane {lane[2]} of {len(lanes)}: there is no lane to its {side}")
        self.original_lane, self.target_lane = lane, (lane[0], lane[1], tid)
        y0, y1 = lanes[lane[2]].position(0.0, 0.0)[1], lanes[tid].position(0.0, 0.0)[1]
        self.frame = LaneFrame(origin_y=float(y0), sign=1.0 if y1 > y0 else -1.0)
        self.t = 0.0
        self.completed = False
        self.costed = False
        self.cut_in = False
        # until the ego lies wholly in the target lane: read by NoCutInIDMVehicle, and for info["cut_in"]
        u.road.safelane_manoeuvre = (self.ego, (self.original_lane, self.target_lane))
        self.shield.reset(self.situation())  # (core.init folds the others into the roles, as every period does)
        self.reset_blame()
        self.in_flight = InFlight.idle(1, self.delay_periods)  # the commands acting at the start: cruise
        obs = u.observation_type.observe()
        info.update(original_lane=lane[2], target_lane=tid, crashed=bool(self.ego.crashed))
        return obs, info

    def step(self, action):
        if self.ego is None:
            raise RuntimeError("SafeLaneShield.step before reset()")
        prm, ego, frame = self.params, self.ego, self.frame
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (2,):
            raise ValueError(f"SafeLaneShield takes actions (a_x, a_y); got shape {np.shape(action)}")
        vx0, vy0 = ego.speed, float(frame.y(0.0, ego.lateral_speed)[1])
        situation = self.situation()  # also names the vehicles around the ego (F, L1, L0) for the crash report
        if self.shield_on:
            decision = self.shield.step(situation, (a[:1], a[1:]))
            code = int(decision.behaviour[0])
            if self.delay_periods:  # the oldest command in flight acts now (exactly); this one joins the queue
                acting, self.in_flight = self.in_flight.push(Command.of(decision))
                ey, evy = frame.y(ego.position[1], ego.lateral_speed)
                ego1 = tuple(np.array([float(q)]) for q in (ego.position[0], ey, ego.speed, evy))
                nx, ny, nv, nvy = acting.carry(*ego1, prm.dt)
                ysim = frame.origin_y + frame.sign * float(ny[0])
                ego.command = ("state", float(nx[0]), float(nv[0]), ysim, frame.sign * float(nvy[0]))
            elif code == ABORT and decision.abort_motion()[0].size:  # the held plan's exact motion over the period
                _, _, px, vx, py, vy = decision.abort_motion()
                ysim = frame.origin_y + frame.sign * float(py[0, -1])
                ego.command = ("state", float(px[0, -1]), float(vx[0, -1]), ysim, frame.sign * float(vy[0, -1]))
            else:
                ego.command = ("accel", float(decision.a_x[0]), float(frame.y_back(decision.a_y[0])))
            name, intervened, reason = BEHAVIOUR[code], bool(decision.intervened[0]), decision.reasons()[0]
        else:
            ok = np.isfinite(a).all()
            ax = float(np.clip(a[0], -prm.a_x_d, prm.a_x_a)) if ok else 0.0
            ay = float(np.clip(a[1], -prm.a_y_m, prm.a_y_m)) if ok else 0.0
            ego.command = ("accel", ax, float(frame.y_back(ay)))
            name, intervened, reason = "off", False, "shield off: the action as given (clipped)"
        obs, reward, terminated, truncated, info = self.env.step(self._host_action())
        self.t += prm.dt
        y, vy1 = (float(z) for z in frame.y(ego.position[1], ego.lateral_speed))
        self.completed = self.completed or y >= prm.y_boundary
        road = self.env.unwrapped.road
        if getattr(road, "safelane_manoeuvre", None) is not None:
            self.cut_in = self.cut_in or any(
                getattr(v, "target_lane_index", v.lane_index) != v.lane_index and cuts_in(v, v.target_lane_index)
                for v in road.vehicles
            )  # fmt: skip
            if y >= prm.lane_width - prm.y_safe:
                road.safelane_manoeuvre = None
        cost = 0.0
        if ego.crashed:
            cost = 1.0
        elif not self.costed and y > prm.y_safe:
            front, rear = road.neighbour_vehicles(ego, self.target_lane)
            close = (front is not None and front.position[0] - ego.position[0] < prm.p_m) or (
                rear is not None and ego.position[0] - rear.position[0] < prm.p_m)  # fmt: skip
            if close:
                cost, self.costed = 1.0, True
        self._observe_blame()
        if ego.crashed and self.crash_blame is None:
            partner = crash_partner(ego, road)
            if partner is not None:
                b = self.blame.verdict([id(partner)])
                self.crash_blame = (b.labels()[0], b.clause_names()[0], float(b.blame_t[0]))
        info.update(
            shield=name, intervened=intervened, nominal_action=a.copy(),
            executed_action=np.array([(ego.speed - vx0) / prm.dt, (vy1 - vy0) / prm.dt]), reason=reason, cost=cost,
            completed=self.completed, cut_in=self.cut_in, crashed=bool(ego.crashed),
            crash_blame=self.crash_blame[0] if ego.crashed and self.crash_blame else None,
        )  # fmt: skip
        if ego.crashed:
            info["crash"] = classify_crash(ego, self.env.unwrapped.road, self.roles, frame, prm, self.original_lane,
                                           self.target_lane)  # fmt: skip
            if self.crash_blame:
                info["crash"].update(blame_clause=self.crash_blame[1], blame_t=round(self.crash_blame[2], 3))
        return obs, reward, terminated, truncated, info


register_highway_envs()
