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
from .behaviours import follower_accel, leader_accels, leader_roles, responsible_accel
from .checks import ego_checks, lane_checks, lane_pairs
from .config import SimConfig
from .kinematics import Fleet, Motion
from .rng import counter_normal, counter_uniform
from .scenario import ScenarioBatch
from .supervisor import ABORT, COMPLETED, HESITATE, PROCEED, check_candidate, hesitate_lateral, plan_motion


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


class ClosedLoop:
    """Holds the constant per-scenario arrays; ``step`` is a pure function of the state."""

    def __init__(self, batch: ScenarioBatch, seed: int, prm: Params, cfg: SimConfig, nominal: NominalPlanner):
        # (B, K) arrays are kept column-major: the engine works vehicle by vehicle (x[:, i]), and a strided
        # column costs NumPy several times a contiguous one.
        batch = dataclasses.replace(
            batch, **{f.name: _columns(getattr(batch, f.name)) for f in dataclasses.fields(batch)}
        )
        self.b, self.seed, self.prm, self.cfg, self.nominal = batch, seed, prm, cfg, nominal
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

    def worst_case(self, s: SimState, belief: assess.AssessmentState):
        """L1's worst-case deceleration and F's assumed type, from the information each variant uses."""
        b, prm = self.b, self.prm
        n_links = s.x.shape[1] - 2
        with np.errstate(all="ignore"):  # inputs were checked with the batch: the scan alone, unchecked
            decel, _, unsafe = propagate_chain(
                ARRAY, s.x.T[1:], s.v.T[1:], self.chain_promise, self.chain_margin, prm, n_links
            )
        l1_decel = np.where(self.uses_chain & ~np.asarray(unsafe, bool), decel[0], prm.a_x_d)
        assessed = b.follower_aggressive if self.cfg.assessment == "truth" else belief.aggressive
        trusted = self.uses_f_v2x & b.connected[:, 0]
        f_aggr = np.where(trusted, False, np.where(self.uses_assessment, assessed, True))
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
        l1_decel, f_aggr = self.worst_case(s, belief)
        a_x, a_y = clip_actions(*self.nominal(obs, prm), prm)  # a planner's own clipping is not trusted
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
                if rows.size == 0:
                    break
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

        acc = self.others_accels(s, ex, evx)
        others = Fleet.constant(s.x, s.v, acc, dt)
        new_plan = _set_rows(s.plan, accepted)
        new = self.check_and_advance(s, lon, lat, plan, others, behaviour, completing, new_plan, acc, belief)
        return new, obs, behaviour

    def others_accels(self, s: SimState, ex, evx):
        b, prm, cfg = self.b, self.prm, self.cfg
        k = s.x.shape[1]
        slots = np.arange(k)
        violating = pick = None  # counter-based: skipping the draws when p_v = 0 everywhere changes nothing else
        if self.any_violation:
            violating = counter_uniform(self.seed, b.scenario_id[:, None], s.step, slots[None, :], 7) < b.p_v[:, None]
            pick = counter_uniform(self.seed, b.scenario_id[:, None], s.step, slots[None, :], 8)
        braking = np.full(len(b), s.t + 1e-9 >= cfg.brake_start_s)
        acc = leader_accels(
            s.x,
            s.v,
            self.margin,
            self.roles,
            b.promise_decel,
            b.promise_accel,
            self.v_desired,
            b.decel_last,
            braking,
            violating,
            pick,
            prm,
        )
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
        )
        return acc

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
