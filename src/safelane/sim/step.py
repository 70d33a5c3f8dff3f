"""One control period of the batched closed loop, for every scenario at once.

:class:`ClosedLoop` holds a batch's constant arrays; :meth:`ClosedLoop.step` maps a :class:`SimState` to the next:
observe → assess F → worst-case analysis by variant → nominal planner → supervisor → other vehicles act → exact
integration → continuous-time collision checks. Per-vehicle ``(B, K)`` arrays are kept column-major.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..planners.base import NominalPlanner, Observation, clip_actions
from ..planners.variants import VARIANT_NAMES, VARIANTS
from ..safety._backend import ARRAY
from ..safety.chain import propagate_chain
from ..safety.evasion import plan_evasion
from ..safety.lateral import LATERAL_TOL_M
from ..safety.plan import EvasionPlan
from . import assessment as assess
from .behaviours import follower_accel, leader_accels, leader_roles, leader_task, responsible_accel
from .checks import ego_checks, lane_checks, lane_pairs
from .config import SimConfig
from .kinematics import Fleet, Motion
from .link import Link
from .monitor import Breach, observe_breaches
from .proposals import check_proposal
from .rng import counter_normal, counter_uniform
from .scenario import ScenarioBatch
from .supervisor import ABORT, COMPLETED, HESITATE, PROCEED, check_candidate, hesitate_lateral, plan_motion
from .traffic import TrafficHooks, TrafficView, hook_output, profile_segment


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
    plan: EvasionPlan
    plan_t0: np.ndarray
    belief: assess.AssessmentState
    collided: np.ndarray
    violated: np.ndarray
    leader_collided: np.ndarray
    leader_violated: np.ndarray
    min_gap_f: np.ndarray
    min_gap_l1: np.ndarray
    counts: np.ndarray  # (B, 3) proceed / hesitate / abort
    plan_f_aggr: np.ndarray  # (B,) the F type the held plan assumed
    breach: Breach  # the assumption monitor's record
    n_invalid: np.ndarray  # (B,) periods whose nominal proposal was invalid (non-finite or out of range)
    leader_cap: np.ndarray  # (B, K) the smallest chain bound each vehicle has had: it never brakes harder
    link: Link | None = None  # the V2X emulation's received messages (None: perfect V2X)


class ClosedLoop:
    """Holds the constant per-scenario arrays; ``step`` is a pure function of the state."""

    def __init__(
        self,
        batch: ScenarioBatch,
        seed: int,
        prm: Params,
        cfg: SimConfig,
        nominal: NominalPlanner,
        traffic: TrafficHooks | None = None,
    ):
        # (B, K) arrays are kept column-major: the engine works vehicle by vehicle (x[:, i]), and a strided
        # column costs NumPy several times a contiguous one.
        batch = dataclasses.replace(
            batch, **{f.name: _columns(getattr(batch, f.name)) for f in dataclasses.fields(batch)}
        )
        self.b, self.seed, self.prm, self.cfg, self.nominal = batch, seed, prm, cfg, nominal
        self.traffic = traffic or TrafficHooks()
        variants = [VARIANTS[name] for name in VARIANT_NAMES]
        self.uses_chain = np.array([v.uses_chain for v in variants])[batch.variant]
        self.uses_f_v2x = np.array([v.uses_follower_v2x for v in variants])[batch.variant]
        self.uses_assessment = np.array([v.uses_assessment for v in variants])[batch.variant]
        k = batch.x.shape[1]
        slots = np.arange(1, k)
        in_chain = slots[None, :] <= batch.n_connected[:, None]
        # The chain's inputs as contiguous rows (vehicle-major), for the unchecked scan of the chain.
        self.chain_promise = np.where(in_chain, batch.promise_decel[:, 1:], prm.a_x_d)[:, :-1].T.copy()
        self.chain_margin = np.where((batch.human[:, 1:] & in_chain)[:, :-1].T, prm.p_m_human, prm.p_m)
        self.gap0 = batch.ego_x - batch.x[:, 0]
        self.any_violation = bool((batch.p_v > 0.0).any())
        self.v_desired = batch.v.copy(order="F")
        self.margin = np.where(batch.human, prm.p_m_human, prm.p_m)
        self.roles = leader_roles(batch.valid, batch.connected, batch.n_connected)
        self.lane_pairs = lane_pairs(batch, prm)
        self.last_slot = batch.n_connected + 1
        self.emulate_v2x = cfg.v2x_loss > 0.0 or cfg.v2x_latency_periods > 0
        self.chain_connected = np.column_stack([in_chain, np.zeros(len(batch), bool)])[:, : k - 1]
        self.last_slot_mask = np.arange(k)[None, :] == self.last_slot[:, None]

    def initial_state(self) -> SimState:
        b, prm = self.b, self.prm
        n = len(b)
        # The plan held at t = 0: from the initial state under the most conservative assumptions.
        ego = (b.ego_x, b.ego_y, b.ego_vx, b.ego_vy)
        plan = plan_evasion(*ego, b.x[:, 1], b.v[:, 1], prm.a_x_d, b.x[:, 0], b.v[:, 0], True, prm)
        return SimState(
            t=0.0,
            step=0,
            ego=(b.ego_x.copy(), b.ego_y.copy(), b.ego_vx.copy(), b.ego_vy.copy()),
            x=b.x.copy(order="F"),
            v=b.v.copy(order="F"),
            acc=np.zeros_like(b.x, order="F"),
            completed=np.zeros(n, bool),
            t_complete=np.full(n, np.nan),
            plan=plan,
            plan_t0=np.zeros(n),
            belief=assess.AssessmentState.start(n, self.cfg.assess_window),
            collided=np.zeros(n, bool),
            violated=np.zeros(n, bool),
            leader_collided=np.zeros(n, bool),
            leader_violated=np.zeros(n, bool),
            min_gap_f=np.full(n, np.inf),
            min_gap_l1=np.full(n, np.inf),
            counts=np.zeros((n, 3), np.int64),
            plan_f_aggr=np.ones(n, bool),
            breach=Breach.none(n),
            n_invalid=np.zeros(n, np.int64),
            leader_cap=np.full(b.x.shape, np.inf),
            link=Link.start(b.x, b.v) if self.emulate_v2x else None,
        )

    def observe(self, s: SimState) -> Observation:
        b = self.b
        ex, ey, evx, evy = s.ego
        l1_plan = np.where((self.uses_chain & (b.n_connected >= 1))[:, None], s.acc[:, 1:2], 0.0) * np.ones(
            (1, self.cfg.l1_plan_steps)
        )
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
        )

    def chain(self, s: SimState):
        """The chain analysis on the current states: ``(bounds (B, K), unsafe (B,))``, ``bounds[:, i]`` the worst-case
        deceleration of slot ``i`` (``a_x_d`` for F's slot, ``L(N+1)`` and anything not connected)."""
        prm = self.prm
        n_links = s.x.shape[1] - 2
        with np.errstate(all="ignore"):  # inputs were checked with the batch: the scan alone, unchecked
            decel, _, unsafe = propagate_chain(
                ARRAY, s.x.T[1:], s.v.T[1:], self.chain_promise, self.chain_margin, prm, n_links
            )
        bounds = np.column_stack([np.full(len(s.x), prm.a_x_d), *(np.broadcast_to(d, (len(s.x),)) for d in decel)])
        return bounds, np.broadcast_to(np.asarray(unsafe, bool), (len(s.x),))

    def ego_chain(self, s: SimState, link: Link | None, chain):
        """What the ego's analysis gives for ``L1``: ``(bound, unsafe, stale (B,), f_fresh (B,))``. With perfect V2X
        the chain on the true states (``chain``); with the emulation, on the ego's view through the staleness
        fallback."""
        n = len(s.x)
        if link is None:
            return chain[0][:, 1], chain[1], np.zeros(n, bool), np.ones(n, bool)
        prm, cfg = self.prm, self.cfg
        p, v, n_eff, stale = link.chain_view(s.t, s.x[:, 1], s.v[:, 1], self.chain_connected, prm, cfg.v2x_max_age_s)
        links = np.arange(p.shape[1] - 1)[:, None]
        promise = np.where(links < n_eff[None, :], self.chain_promise, prm.a_x_d)
        with np.errstate(all="ignore"):
            decel, _, unsafe = propagate_chain(ARRAY, p.T, v.T, promise, self.chain_margin, prm, p.shape[1] - 1)
        f_fresh = link.fresh(0, s.t, cfg.v2x_max_age_s)
        stale_any = stale.any(1) | (self.b.connected[:, 0] & ~f_fresh)
        return np.broadcast_to(decel[0], (n,)), np.broadcast_to(np.asarray(unsafe, bool), (n,)), stale_any, f_fresh

    def worst_case(self, s: SimState, belief: assess.AssessmentState, l1_bound, unsafe, f_fresh):
        """L1's worst-case deceleration and F's assumed type, from the information each variant uses; after a
        breach of the assumptions (the monitor, ``SimConfig.monitor``) the most conservative ones."""
        b, prm = self.b, self.prm
        l1_decel = np.where(self.uses_chain & ~unsafe, l1_bound, prm.a_x_d)
        assessed = b.follower_aggressive if self.cfg.assessment == "truth" else belief.aggressive
        trusted = self.uses_f_v2x & b.connected[:, 0] & f_fresh
        f_aggr = np.where(trusted, False, np.where(self.uses_assessment, assessed, True))
        if self.cfg.monitor:
            broken = s.breach.any
            l1_decel = np.where(broken, prm.a_x_d, l1_decel)
            f_aggr = f_aggr | broken
        return l1_decel, f_aggr

    def step(self, s: SimState):
        b, prm, cfg = self.b, self.prm, self.cfg
        dt = prm.dt
        ex, ey, evx, evy = s.ego
        obs = self.observe(s)
        observed_f_v = s.v[:, 0]
        if cfg.sensor_noise_std > 0.0:  # counter-based: skipping the draws when unused changes nothing else
            observed_f_v = observed_f_v + cfg.sensor_noise_std * counter_normal(self.seed, b.scenario_id, s.step, 0)
        belief = assess.update(s.belief, observed_f_v, s.t, dt, cfg.assess_threshold)
        chain = self.chain(s)
        link = s.link
        if link is not None:
            link = link.update(
                s.t, s.x, s.v, s.acc, s.step, self.seed, b.scenario_id, cfg.v2x_loss, cfg.v2x_latency_periods
            )
        l1_bound, unsafe, stale, f_fresh = self.ego_chain(s, link, chain)
        l1_decel, f_aggr = self.worst_case(s, belief, l1_bound, unsafe, f_fresh)
        # A planner's answer is checked, not trusted: a wrong shape or type is an error naming it; a non-finite or
        # out-of-range action is a failed proposal (the row hesitates on a safe command or aborts).
        a_x, a_y, invalid = check_proposal(self.nominal, self.nominal(obs, prm), len(b), prm)
        a_x, a_y = clip_actions(a_x, a_y, prm)
        l1x, l1v, fx, fv = s.x[:, 1], s.v[:, 1], s.x[:, 0], s.v[:, 0]

        active = ~s.completed
        behaviour = np.where(active, PROCEED, COMPLETED)
        completing = np.zeros(len(b), bool)
        accepted = []  # (rows, their verified plans) of this period
        a_yh = hesitate_lateral(evy, prm)
        if cfg.supervised:
            # The supervisor runs only where the lane change is under way; hesitate only where proceed failed.
            rows = np.flatnonzero(active)
            for code, lateral in ((PROCEED, a_y), (HESITATE, a_yh)):
                if code == PROCEED:  # an invalid proposal is never executed: those rows start at hesitate
                    skip, rows = rows[invalid[rows]], rows[~invalid[rows]]
                elif skip.size:
                    rows = np.sort(np.concatenate([rows, skip]))
                if rows.size == 0:
                    continue
                verdict = check_candidate(
                    *(a[rows] for a in (ex, ey, evx, evy, a_x, lateral, l1x, l1v, l1_decel, fx, fv, f_aggr)), prm
                )
                ok_rows = rows[verdict.ok]
                behaviour[ok_rows] = code
                completing[ok_rows] = verdict.completing[verdict.ok]
                accepted.extend((rows[idx], plan) for idx, plan in verdict.plans)
                rows = rows[~verdict.ok]
            behaviour[rows] = ABORT
        else:
            completing = active & (ey + evy * dt + 0.5 * a_y * dt * dt >= prm.y_boundary)

        # Post-completion: centre in the target lane, follow L1 responsibly under its worst case.
        done = np.flatnonzero(s.completed)
        ax_cmd = a_x.copy()
        ay_cmd = np.where(behaviour == HESITATE, a_yh, a_y)
        if done.size:
            ax_cmd[done] = responsible_accel(
                a_x[done], (l1x - ex - prm.p_m)[done], evx[done], l1v[done], l1_decel[done], prm
            )
            ay_cmd[done] = np.clip(0.8 * (prm.lane_width - ey[done]) - 1.6 * evy[done], -prm.a_y_m, prm.a_y_m)
        lon = Motion.constant(ex, evx, ax_cmd, dt)
        lat = Motion.free(ey, evy, ay_cmd, dt)
        plan = None
        rows = np.flatnonzero(behaviour == ABORT)
        if rows.size:  # only the aborting rows follow their plan: evaluate it there alone
            plan = (rows, *plan_motion(s.plan.take(rows), s.t - s.plan_t0[rows], dt))

        # A leader's bound never grows in exact arithmetic (docs/simulator.md); the running minimum makes that exact
        # in floating point too (the analysis' 1 nm tolerance lets a recomputed bound exceed an earlier one by ~1e-9).
        leader_cap = np.minimum(s.leader_cap, chain[0])
        acc, last_switch = self.others_accels(s, ex, evx, ey, evy, leader_cap)
        if last_switch is None:
            others = Fleet.constant(s.x, s.v, acc, dt)
        else:  # L(N+1)'s profile switches inside the period: its slot gets a second segment
            t_sw, a2 = last_switch
            others = Fleet.switched(s.x, s.v, acc, t_sw, a2, dt)
        new_plan = _set_rows(s.plan, accepted)
        plan_f_aggr = s.plan_f_aggr.copy()
        for rows_acc, _ in accepted:
            plan_f_aggr[rows_acc] = f_aggr[rows_acc]
        # The monitor compares what the others did this period with what the held plan assumed; the supervisor
        # sees the result from the next period on (it is observed at the period's end).
        breach = observe_breaches(
            s.breach, s, acc, chain[0], s.plan.l1_decel, s.plan_f_aggr, active, prm, s.t + dt, last_switch,
            self.last_slot, stale,
        )
        new = self.check_and_advance(s, lon, lat, plan, others, behaviour, completing, new_plan, acc, belief)
        new = dataclasses.replace(
            new,
            plan_f_aggr=plan_f_aggr,
            breach=breach,
            n_invalid=s.n_invalid + (invalid & active),
            leader_cap=leader_cap,
            link=link,
        )
        _check_finite(new, b)
        return new, obs, behaviour

    def others_accels(self, s: SimState, ex, evx, ey, evy, bounds):
        """Accelerations of the target-lane vehicles for this period ``(B, K)`` and L(N+1)'s switch inside it
        (``(t_switch (B, K), a2 (B, K))``, ``t_switch = dt`` elsewhere) or ``None``."""
        b, prm, cfg = self.b, self.prm, self.cfg
        k = s.x.shape[1]
        slots = np.arange(k)
        violating = pick = None  # counter-based: skipping the draws when p_v = 0 everywhere changes nothing else
        if self.any_violation:
            violating = counter_uniform(self.seed, b.scenario_id[:, None], s.step, slots[None, :], 7) < b.p_v[:, None]
            pick = counter_uniform(self.seed, b.scenario_id[:, None], s.step, slots[None, :], 8)
        hooks = self.traffic
        view = None
        if hooks.leader_task is not None or hooks.follower_wish is not None:
            view = TrafficView(
                t=s.t, scenario_id=b.scenario_id, x=s.x, v=s.v, n_connected=b.n_connected, ego_x=ex, ego_y=ey,
                ego_vx=evx, ego_vy=evy, completed=s.completed, follower_aggressive=b.follower_aggressive,
            )
        wanted = None
        if hooks.leader_task is not None:
            wanted = hook_output("leader_task", hooks.leader_task(view, prm), s.x.shape)
        task = leader_task(s.v, self.v_desired, b.promise_decel, b.promise_accel, wanted)
        switch = None
        if b.last_profile_t is None:
            a_last = np.where(s.t + 1e-9 >= cfg.brake_start_s, -b.decel_last, 0.0)
        else:
            a_last, t_sw, a2 = profile_segment(s.t, prm.dt, b.last_profile_t, b.last_profile_a)
            if (t_sw < prm.dt).any():
                on = self.last_slot_mask & (t_sw < prm.dt)[:, None]
                switch = (np.where(on, t_sw[:, None], prm.dt), np.where(on, a2[:, None], 0.0))
        acc = leader_accels(
            s.x, s.v, self.margin, self.roles, bounds, task, a_last, b.decel_last, violating, pick, prm
        )
        f_wish = None
        if hooks.follower_wish is not None:
            f_wish = np.clip(hook_output("follower_wish", hooks.follower_wish(view, prm), (len(b),)), -prm.a_x_d,
                             prm.a_x_a)
        acc[:, 0] = follower_accel(
            s.x[:, 0],
            s.v[:, 0],
            s.x[:, 1],
            s.v[:, 1],
            ex,
            evx,
            b.follower_aggressive,
            s.completed,
            self.gap0,
            prm,
            cfg.follower_open_decel,
            cfg.follower_open_gap_m,
            wanted=f_wish,
            ignores_ego=cfg.follower_ignores_ego,
        )
        return acc, switch

    def check_and_advance(self, s, lon, lat, plan, others, behaviour, completing, new_plan, acc, belief) -> SimState:
        prm = self.prm
        dt = prm.dt
        conflict_level = prm.y_safe + LATERAL_TOL_M
        overlap_level = prm.lane_width - prm.vehicle_width
        collided, violated, min_gap_f, min_gap_l1 = ego_checks(
            self.b, prm, s, lon, lat, others, conflict_level, overlap_level, plan
        )

        leader_collided, leader_violated = lane_checks(self.b, prm, others, self.lane_pairs)

        ex1, evx1 = lon.end
        ey1, evy1 = lat.end
        if plan is not None:  # the aborting rows end where their plans take them
            rows, plan_lon, plan_lat = plan
            ex1, evx1, ey1, evy1 = (a.copy() for a in (ex1, evx1, ey1, evy1))
            (ex1[rows], evx1[rows]), (ey1[rows], evy1[rows]) = plan_lon.end, plan_lat.end
        x1, v1 = others.end
        completed_now = ~s.completed & completing
        replanned = (behaviour == PROCEED) | (behaviour == HESITATE)
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
            plan=new_plan,
            plan_t0=np.where(replanned, s.t + dt, s.plan_t0),
            belief=belief,
            collided=s.collided | collided,
            violated=s.violated | violated,
            leader_collided=s.leader_collided | leader_collided,
            leader_violated=s.leader_violated | leader_violated,
            min_gap_f=min_gap_f,
            min_gap_l1=min_gap_l1,
            counts=counts,
            plan_f_aggr=s.plan_f_aggr,
            breach=s.breach,
            n_invalid=s.n_invalid,
            leader_cap=s.leader_cap,
            link=s.link,
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


def _set_rows(plan: EvasionPlan, pieces) -> EvasionPlan:
    """``plan`` with the rows of each ``(rows, sub_plan)`` piece replaced by ``sub_plan`` (same order); each field
    is copied once."""
    pieces = [(rows, sub) for rows, sub in pieces if rows.size]
    if not pieces:
        return plan
    out = {}
    for f in dataclasses.fields(plan):
        if f.name == "params":
            continue
        arr = getattr(plan, f.name).copy()
        for rows, sub in pieces:
            arr[rows] = getattr(sub, f.name)
        out[f.name] = arr
    return EvasionPlan(**out, params=plan.params)
