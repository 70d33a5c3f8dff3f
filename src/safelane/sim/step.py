"""One control period of the batched closed loop, for every scenario at once.

:class:`ClosedLoop` holds a batch's constant arrays; :meth:`ClosedLoop.step` maps a :class:`SimState` to the next:
observe → nominal planner → **the shield** (:mod:`safelane.shield`, through its public interface: a
:class:`~safelane.shield.Situation` and the proposal in, a :class:`~safelane.shield.Decision` out) → other vehicles
act (traffic) → exact integration → continuous-time collision checks. Per-vehicle ``(B, K)`` arrays are kept
column-major.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..planners.base import NominalPlanner, Observation
from ..planners.variants import VARIANT_NAMES, VARIANTS
from ..safety.lateral import LATERAL_TOL_M
from ..shield import ABORT, HESITATE, PROCEED, ShieldState, Situation
from ..shield import core as shield
from ..shield.command import Command, InFlight
from ..shield.realworld import delay_periods
from . import blame_log
from .behaviours import lane_bounds
from .checks import ego_checks, lane_checks, lane_pairs
from .config import SimConfig
from .kinematics import Fleet, Motion
from .link import Link
from .neighbours import Neighbours
from .own_chain import OwnLane
from .own_chain import start as own_start
from .realworld import executed_motion, measure, own_lane_checks, with_own_lane
from .rng import counter_normal
from .scenario import ScenarioBatch
from .traffic import TrafficView, resolve_traffic


@dataclass(frozen=True)
class SimState:
    """Everything that evolves; arrays have the batch on the leading axis."""

    t: float
    step: int
    ego: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # x, y, vx, vy
    x: np.ndarray  # (B, K) target-lane vehicles
    v: np.ndarray
    acc: np.ndarray  # accelerations applied in the last period
    completed: np.ndarray
    t_complete: np.ndarray
    shield: ShieldState  # the shield's own state (held plan, belief about F, assumption monitor)
    collided: np.ndarray
    violated: np.ndarray
    leader_collided: np.ndarray
    leader_violated: np.ndarray
    min_gap_f: np.ndarray
    min_gap_l1: np.ndarray
    min_lane_ratio: np.ndarray  # (B,) smallest gap / margin between consecutive target-lane vehicles so far
    counts: np.ndarray  # (B, 3) proceed / hesitate / abort
    n_invalid: np.ndarray  # (B,) periods whose nominal proposal was invalid (non-finite or out of range)
    leader_cap: np.ndarray  # (B, K) the smallest chain bound each vehicle has had: it never brakes harder
    link: Link | None = None  # the V2X emulation's received messages (None: perfect V2X)
    l0: tuple | None = None  # (x, v) (B, K) of the own lane, L0 first (sim/own_chain.py); None: the paper's empty lane
    own_cap: np.ndarray | None = None  # (B, K) the smallest chain bound each own-lane vehicle has had
    own_pair_collided: np.ndarray | None = None  # (B,) own-lane vehicles ran into each other (the traffic's soundness)
    l0_collided: np.ndarray | None = None
    l0_violated: np.ndarray | None = None
    min_gap_l0: np.ndarray | None = None
    in_flight: InFlight | None = None  # commands issued but not acting yet (actuation delay), oldest first
    initial_safe: np.ndarray | None = None  # the shield's initial plan is a safe evasion (inside the assumptions)
    blame: blame_log.SimBlame | None = None  # who is responsible for the first events (None: not recorded)

    @property
    def belief(self):
        return self.shield.belief

    @property
    def breach(self):
        return self.shield.breach

    @property
    def plan(self):
        return self.shield.plan


class ClosedLoop:
    """Holds the constant per-scenario arrays; ``step`` is a pure function of the state."""

    def __init__(
        self,
        batch: ScenarioBatch,
        seed: int,
        prm: Params,
        cfg: SimConfig,
        nominal: NominalPlanner,
        traffic=None,
        blame=None,
    ):
        if cfg.own_lane:
            batch = with_own_lane(batch, seed, cfg, prm)
        # (B, K) arrays are kept column-major: the engine works vehicle by vehicle (x[:, i]), and a strided
        # column costs NumPy several times a contiguous one.
        batch = dataclasses.replace(
            batch, **{f.name: _columns(getattr(batch, f.name)) for f in dataclasses.fields(batch)}
        )
        self.b, self.seed, self.prm, self.cfg, self.nominal = batch, seed, prm, cfg, nominal
        # The blame rule's followers (sim/blame_log.py): None off, True with RssParams.matched(prm), or RssParams.
        self.blame = blame
        self.traffic_step = resolve_traffic(traffic).bind(batch, seed, prm, cfg)
        self.uses_chain = np.array([VARIANTS[name].uses_chain for name in VARIANT_NAMES])[batch.variant]
        #: The rows whose L1 shares its plan with the ego (the observation's ``l1_plan``: its last acceleration held).
        self.shares_plan = self.uses_chain & (batch.n_connected >= 1)
        self.shield_config = cfg.shield
        self.delay_periods = delay_periods(cfg, prm)
        self.sensing = cfg.sensing_bounds() if cfg.sensing_error else None
        self.planner_name = getattr(nominal, "__name__", type(nominal).__name__)
        k = batch.x.shape[1]
        slots = np.arange(1, k)
        in_chain = slots[None, :] <= batch.n_connected[:, None]
        # The chain's inputs as contiguous rows (vehicle-major), for the unchecked scan of the chain.
        self.chain_promise = np.where(in_chain, batch.promise_decel[:, 1:], prm.others_decel)[:, :-1].T.copy()
        self.chain_margin = np.where((batch.human[:, 1:] & in_chain)[:, :-1].T, prm.p_m_human, prm.p_m)
        self.lane_pairs = lane_pairs(batch, prm)
        self.last_slot = batch.n_connected + 1
        self.emulate_v2x = cfg.v2x_loss > 0.0 or cfg.v2x_latency_periods > 0
        self.chain_connected = np.column_stack([in_chain, np.zeros(len(batch), bool)])[:, : k - 1]
        self.situation_promise = batch.promise_decel[:, 1:-1]
        self.situation_human = batch.human[:, 1:-1]
        self.neighbours = Neighbours(batch, seed, cfg, prm) if cfg.neighbours else None
        self.own = None if batch.l0_x is None else OwnLane.of(batch, prm)

    def initial_state(self) -> SimState:
        b = self.b
        n = len(b)
        link = Link.start(b.x, b.v) if self.emulate_v2x else None
        x, v = b.x.copy(order="F"), b.v.copy(order="F")
        ego = (b.ego_x.copy(), b.ego_y.copy(), b.ego_vx.copy(), b.ego_vy.copy())
        l0 = None if self.own is None else own_start(b)
        start = self.situation(0.0, ego, x, v, None, b.v[:, 0], l0)
        if self.sensing is not None:
            start = measure(self.seed, b, -1, start, self.sensing, self.cfg.sensing_edge_share)
        in_flight = None
        if self.delay_periods:  # the commands acting when the run starts: cruise
            in_flight = InFlight.idle(n, self.delay_periods)
        start_state = shield.init(start, self.prm, self.shield_config, b.variant)
        return SimState(
            t=0.0,
            step=0,
            ego=ego,
            x=x,
            v=v,
            acc=np.zeros_like(b.x, order="F"),
            completed=np.zeros(n, bool),
            t_complete=np.full(n, np.nan),
            shield=start_state,
            initial_safe=start_state.plan.feasible.copy(),
            collided=np.zeros(n, bool),
            violated=np.zeros(n, bool),
            leader_collided=np.zeros(n, bool),
            leader_violated=np.zeros(n, bool),
            min_gap_f=np.full(n, np.inf),
            min_gap_l1=np.full(n, np.inf),
            min_lane_ratio=np.full(n, np.inf),
            counts=np.zeros((n, 3), np.int64),
            n_invalid=np.zeros(n, np.int64),
            leader_cap=np.full(b.x.shape, np.inf),
            link=link,
            l0=l0,
            own_cap=None if l0 is None else np.full(l0[0].shape, np.inf),
            own_pair_collided=None if l0 is None else np.zeros(n, bool),
            l0_collided=None if l0 is None else np.zeros(n, bool),
            l0_violated=None if l0 is None else np.zeros(n, bool),
            min_gap_l0=None if l0 is None else np.full(n, np.inf),
            in_flight=in_flight,
            blame=self._blame_start(ego, x, v, l0),
        )

    def _blame_start(self, ego, x, v, l0):
        """The blame rule's followers after the first sample (``None`` where blame is not recorded)."""
        if not self.blame:
            return None
        return blame_log.begin(self.b, self.prm, None if self.blame is True else self.blame, ego, x, v, l0)

    def situation(self, t: float, ego, x, v, link: Link | None, f_speed_observed, l0=None) -> Situation:
        """What the ego knows: the true states with perfect V2X, else its view through the staleness fallback. A
        connected F declares itself collaborative (the paper's connected followers are)."""
        b = self.b
        f_connected, stale = b.connected[:, 0], None
        chain_x, chain_v, n_connected = x[:, 1:], v[:, 1:], b.n_connected
        if link is not None:
            cfg = self.cfg
            chain_x, chain_v, n_connected, stale = link.chain_view(t, x[:, 1], v[:, 1], self.chain_connected,
                                                                   self.prm, cfg.v2x_max_age_s)  # fmt: skip
            f_fresh = link.fresh(0, t, cfg.v2x_max_age_s)
            stale = stale.any(1) | (f_connected & ~f_fresh)
            f_connected = f_connected & f_fresh
        return Situation(
            t=t, ego_x=ego[0], ego_y=ego[1], ego_vx=ego[2], ego_vy=ego[3], f_x=x[:, 0], f_v=v[:, 0],
            f_connected=f_connected, f_collaborative=b.connected[:, 0], chain_x=chain_x, chain_v=chain_v,
            chain_promise=self.situation_promise, chain_human=self.situation_human, n_connected=n_connected,
            f_speed_observed=f_speed_observed, f_aggressive_truth=b.follower_aggressive, v2x_stale=stale,
            others=None if self.neighbours is None else self.neighbours.at(t),
            **({} if l0 is None else self.own.situation_fields(*l0)),
        )  # fmt: skip

    def observe(self, s: SimState) -> Observation:
        b = self.b
        ex, ey, evx, evy = s.ego
        l1_plan = np.empty((len(b), self.cfg.l1_plan_steps))  # L1's last acceleration, held over the plan
        l1_plan[:] = np.where(self.shares_plan[:, None], s.acc[:, 1:2], 0.0)
        return Observation(
            p_x=ex,
            p_y=ey,
            v_x=evx,
            v_y=evy,
            p_x_l=s.x[:, 1],
            v_x_l=s.v[:, 1],
            p_x_f=s.x[:, 0],
            v_x_f=s.v[:, 0],
            l1_plan=l1_plan,
            l1_connected=b.connected[:, 1],
            f_connected=b.connected[:, 0],
            completed=s.completed,
            t=s.t,
            scenario_id=b.scenario_id,
        )

    def chain(self, s: SimState):
        """The chain analysis on the current states: ``(bounds (B, K), unsafe (B,))``, ``bounds[:, i]`` the worst-case
        deceleration of slot ``i`` (the others' maximum ``a_o_d`` for F's slot, ``L(N+1)`` and anything not
        connected)."""
        return lane_bounds(s.x, s.v, self.chain_promise, self.chain_margin, self.prm)

    def step(self, s: SimState):
        b, prm, cfg = self.b, self.prm, self.cfg
        dt = prm.dt
        ex, ey, evx, evy = s.ego
        obs = self.observe(s)
        observed_f_v = s.v[:, 0]
        if cfg.sensor_noise_std > 0.0:  # counter-based: skipping the draws when unused changes nothing else
            observed_f_v = observed_f_v + cfg.sensor_noise_std * counter_normal(self.seed, b.scenario_id, s.step, 0)
        chain = self.chain(s)
        link = s.link
        if link is not None:
            link = link.update(
                s.t, s.x, s.v, s.acc, s.step, self.seed, b.scenario_id, cfg.v2x_loss, cfg.v2x_latency_periods
            )
        situation = self.situation(s.t, s.ego, s.x, s.v, link, observed_f_v, s.l0)
        if self.sensing is not None:  # the shield sees measurements (and their bounds) only
            situation = measure(self.seed, b, s.step, situation, self.sensing, cfg.sensing_edge_share)
        # With perfect V2X the ego's chain analysis is the traffic's own: hand it over instead of recomputing it.
        known = (chain[0][:, 1:], chain[1]) if link is None and self.sensing is None else None
        shield_state, d = shield.step(
            s.shield, situation, self.nominal(obs, prm), prm, self.shield_config, b.variant,
            planner_name=self.planner_name, chain=known,
        )  # fmt: skip
        behaviour = d.behaviour
        in_flight = s.in_flight
        completing = d.completing
        if self.delay_periods:  # the command acting now is the oldest in flight; this one acts later
            acting, in_flight = in_flight.push(Command.of(d))
            lon, lat, plan = executed_motion(acting, s.ego, dt)
            completing = acting.completing
        else:
            lon = Motion.constant(ex, evx, d.a_x, dt)
            lat = Motion.free(ey, evy, d.a_y, dt)
            plan = None
            rows, knots, px, vx, py, vy = d.abort_motion()
            if rows.size:  # the aborting rows follow their held plan, exactly
                plan = (rows, Motion.from_samples(knots, px, vx), Motion.from_samples(knots, py, vy))

        # A leader's bound never grows in exact arithmetic (docs/simulator.md); the running minimum makes that exact
        # in floating point too (the analysis' 1 nm tolerance lets a recomputed bound exceed an earlier one by ~1e-9).
        leader_cap = np.minimum(s.leader_cap, chain[0])
        acc, last_switch = self.others_accels(s, ex, evx, ey, evy, leader_cap)
        if last_switch is None:
            others = Fleet.constant(s.x, s.v, acc, dt)
        else:  # L(N+1)'s profile switches inside the period: its slot gets a second segment
            t_sw, a2 = last_switch
            others = Fleet.switched(s.x, s.v, acc, t_sw, a2, dt)
        new = self.check_and_advance(s, lon, lat, plan, others, behaviour, completing, acc)
        new = dataclasses.replace(
            new, shield=shield_state, n_invalid=s.n_invalid + d.invalid, leader_cap=leader_cap, link=link,
            in_flight=in_flight,
        )
        if s.l0 is not None:
            new = self._own_lane(s, new, lon, lat, plan)
        if s.blame is not None:
            new = dataclasses.replace(new, blame=blame_log.step(s.blame, s, new, b, prm))
        _check_finite(new, b)
        return new, obs, behaviour

    def _own_lane(self, s: SimState, new: SimState, lon, lat, plan) -> SimState:
        """The own lane drives (sim/own_chain.py); the ego's collisions and p_m violations against L0
        (sim/realworld.py)."""
        prm = self.prm
        present = np.isfinite(s.l0[0])
        fleet, cap = self.own.period(self.b, s.t, s.l0[0], s.l0[1], s.own_cap, prm)
        col, vio, gap = own_lane_checks(prm, lon, lat, plan, fleet.motion(slice(None), 0), present[:, 0],
                                        s.completed)  # fmt: skip
        pair = s.own_pair_collided
        if self.own.slots > 1:
            pair = pair | self.own.pair_collisions(fleet, present, prm)[0]
        x1, v1 = fleet.end
        return dataclasses.replace(
            new, l0=(np.asfortranarray(np.where(present, x1, np.inf)), v1), own_cap=cap, own_pair_collided=pair,
            l0_collided=s.l0_collided | col, l0_violated=s.l0_violated | vio, min_gap_l0=np.minimum(s.min_gap_l0, gap),
            collided=new.collided | col, violated=new.violated | vio,
        )  # fmt: skip

    def finish(self, s: SimState) -> SimState:
        """The state after the last period with the monitor's view of that period recorded (the shield observes a
        period at the start of the next one)."""
        situation = self.situation(s.t, s.ego, s.x, s.v, s.link, s.v[:, 0], s.l0)
        if self.sensing is not None:
            situation = measure(self.seed, self.b, s.step, situation, self.sensing, self.cfg.sensing_edge_share)
        return dataclasses.replace(s, shield=shield.observe(s.shield, situation, self.prm, self.shield_config))

    def others_accels(self, s: SimState, ex, evx, ey, evy, bounds):
        """The traffic model's accelerations of the target-lane vehicles for this period ``(B, K)`` and any switch
        inside it (see :class:`~safelane.sim.traffic.TrafficModel`)."""
        b = self.b
        view = TrafficView(
            t=s.t, scenario_id=b.scenario_id, x=s.x, v=s.v, n_connected=b.n_connected, ego_x=ex, ego_y=ey,
            ego_vx=evx, ego_vy=evy, completed=s.completed, follower_aggressive=b.follower_aggressive, step=s.step,
            bounds=bounds,
        )  # fmt: skip
        return self.traffic_step(view)

    def check_and_advance(self, s, lon, lat, plan, others, behaviour, completing, acc) -> SimState:
        prm = self.prm
        dt = prm.dt
        conflict_level = prm.y_safe + LATERAL_TOL_M
        overlap_level = prm.lane_width - prm.vehicle_width
        collided, violated, min_gap_f, min_gap_l1 = ego_checks(
            self.b, prm, s, lon, lat, others, conflict_level, overlap_level, plan
        )

        leader_collided, leader_violated, lane_ratio = lane_checks(self.b, prm, others, self.lane_pairs)

        ex1, evx1 = lon.end
        ey1, evy1 = lat.end
        if plan is not None:  # the aborting rows end where their plans take them
            rows, plan_lon, plan_lat = plan
            ex1, evx1, ey1, evy1 = (a.copy() for a in (ex1, evx1, ey1, evy1))
            (ex1[rows], evx1[rows]), (ey1[rows], evy1[rows]) = plan_lon.end, plan_lat.end
        x1, v1 = others.end
        completed_now = ~s.completed & completing
        counts = s.counts + np.stack([behaviour == k for k in (PROCEED, HESITATE, ABORT)], 1)
        return SimState(
            t=s.t + dt,
            step=s.step + 1,
            ego=(ex1, ey1, evx1, evy1),
            x=x1,
            v=v1,
            acc=acc,
            completed=s.completed | completed_now,
            t_complete=np.where(completed_now, s.t + dt, s.t_complete),
            shield=s.shield,
            collided=s.collided | collided,
            violated=s.violated | violated,
            leader_collided=s.leader_collided | leader_collided,
            leader_violated=s.leader_violated | leader_violated,
            min_gap_f=min_gap_f,
            min_gap_l1=min_gap_l1,
            min_lane_ratio=np.minimum(s.min_lane_ratio, lane_ratio),
            counts=counts,
            n_invalid=s.n_invalid,
            leader_cap=s.leader_cap,
            link=s.link,
            initial_safe=s.initial_safe,
        )


def _check_finite(s: SimState, b: ScenarioBatch) -> None:
    """A NaN or inf in the state is a bug, never a silent "no collision": stop the run and name the scenarios."""
    ex, ey, evx, evy = s.ego
    bad = ~(np.isfinite(ex) & np.isfinite(ey) & np.isfinite(evx) & np.isfinite(evy))
    bad |= ~np.isfinite(s.x).all(1) | ~np.isfinite(s.v).all(1)
    if bad.any():
        ids = b.scenario_id[bad][:5].tolist()
        raise FloatingPointError(
            f"non-finite simulator state at t = {s.t:.1f} s in scenario(s) {ids} ({int(bad.sum())} in all): a bug in "
            "a behaviour model or hook, not an outcome"
        )


def _columns(a):
    """2-D per-vehicle arrays column-major; everything else as it is."""
    return np.asfortranarray(a) if isinstance(a, np.ndarray) and a.ndim == 2 else a
