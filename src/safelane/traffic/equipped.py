"""Equipped vehicles' lane changes under the shield (docs/traffic.md).

Equipped vehicles are connected: each period they broadcast their state and promise (``PROMISE_DECEL``; the V2X
link is ideal here — no loss or latency —, held as arrays rather than per-vehicle messages). They keep SUMO's
car following, but SUMO never changes their lane (lane-change mode 0): SUMO's LC2013 only *wishes*
(:meth:`.world.TrafficWorld.wishes`, every ``wish_every_s``), and the wish starts a lane change that the shield
executes. While it changes lanes a vehicle is a point mass driven from here (the nominal planner proposes — the
expert, as in the other integrations —, the shield decides, ``moveToXY`` places it), until it has completed and
reached the target lane's centre, or has returned to its own lane's centre: then SUMO drives it again.

**An abort from across the line ends the attempt.** From the first period the shield aborts with the vehicle's
centre in the conflict zone (``y > y_safe``: its body across the lane line; ``resume_s`` later, default at once), or
``give_up_s`` after the start if the change has not completed by then, the vehicle *returns*: its proposal is no
longer the expert's (which wants the target lane and would start the change again as soon as the shield lets it, so
that an aborted change could hover at the lane boundary for tens of seconds) but :func:`return_accel`, back to its
own lane's centre; the shield still decides every period. An abort from inside the own lane is the shield braking
for a period, as in the paper's world, and the attempt goes on. ``return_deadline_s`` is the time a return may take
(``counts["return_max_s"]`` the longest measured, ``counts["return_late"]`` the returns that took longer).

The expert knows the paper's world (F and the chain). Here its proposal is adapted in three ways: a missing F or L1
is placed symmetric to the other (:meth:`LaneChanges._observation`), its braking is limited to
:data:`BRAKE_COMFORT`, and until the change completes its ``a_x`` is capped by :func:`follow_l0`, the own lane's
leader (``l0_aware``).

All changers of a period are one batch: their :class:`~safelane.shield.Situation` is built from the fleet's arrays
by one neighbour search (:func:`.lanes.neighbours`, compiled: F the nearest behind in the target lane, the chain
``L1…L(M)`` ahead of it, the connected ones the equipped vehicles at its head, ``L0`` the nearest ahead in the own
lane — or the end of the acceleration lane, a standing obstacle), and :func:`.shielding.decide` makes one
``Shield.step`` for all of them. A vehicle belongs to
every lane its body overlaps (a vehicle across a lane boundary counts in both).

**The world model** (``others``, off by default): the changers' situation also carries
:class:`~safelane.shield.world.Others` (:func:`.others.others_record`) — the vehicles that can enter a changer's
path without being F, the chain or ``L0``: those in the lane beyond the target lane and in the lane on its other
side (bodies overlapping neither its own nor its target lane), within :data:`OTHERS_WINDOW_M` along the road, the
:data:`OTHERS_SLOTS` nearest. Lateral speeds are SUMO's (zero for its instantaneous lane changes), the changers'
their exact ones. Equipped vehicles are connected, and an equipped vehicle that is changing lanes announces the lane
it will enter (its target; its own lane while it returns) from the period its change started (its wish starts the
change in the period SUMO's LC2013 states it, so a wish is announced as it starts); human vehicles are not
connected (the shield bounds them by RSS's lateral rule). The shield folds the record into its roles
(:func:`safelane.shield.world.roles`).

Connected leaders honour their promises as the guarantee needs: an equipped vehicle among the connected leaders
of a changer's chain brakes at most at its chain bound (``max(promise, bound)``, the smallest over the chains it is
in) in the next step: SUMO's own choice of speed where it is milder, ``v − bound·dt`` where SUMO would brake harder
(:meth:`.world.TrafficWorld.limit_braking`; SUMO's ``decel`` keeps the human value, so Krauss plans as before).
"""

from __future__ import annotations

import numpy as np

from .._motion import advance
from ..params import Params
from ..planners.base import ExpertPlanner, Observation
from ..shield import ABORT, HESITATE, Situation
from ..shield.stages import chain_analysis
from . import demand as dem
from .lanes import neighbours
from .others import OTHERS_SLOTS, OTHERS_WINDOW_M, others_record
from .shielding import ShieldPool, decide

PROMISE_DECEL = 0.5  # [m/s²] the promise every equipped vehicle broadcasts (the SUMO integration's default)
CHAIN_SLOTS = 4  # L1..L4 in the situation: up to N = 3 connected leaders
FAR_M = 1e4
SETTLED_Y_M, SETTLED_VY = 0.05, 0.1
RETURN_OMEGA = 1.0  # [1/s] natural frequency of the return's critically damped lateral law (the expert's: 0.65)
RETURN_HEADWAY_S = 1.0  # the return's longitudinal law keeps this time gap (plus p_m) to L0
#: [m/s²] the expert's comfort limit here: it never proposes braking harder to place the vehicle in the target gap
#: (below the DRAC conflict threshold 3.35 and SUMO's comfortable ``decel`` 4.5; the shield still brakes at up to
#: ``a_x_d`` where safety needs it). Unlimited, it braked at 8 m/s² in the fast lane to drop back into a gap.
BRAKE_COMFORT = 3.0


def follow_l0(ex, evx, ox, ov, prm: Params) -> np.ndarray:
    """The longitudinal acceleration that keeps the own-lane leader ``L0`` (``ox``, ``ov``; ``+inf`` where none)
    ahead: a PD law on the gap beyond ``p_m + RETURN_HEADWAY_S·v`` and on the speed difference (the expert's gains),
    ``+inf`` where there is no ``L0``."""
    with np.errstate(invalid="ignore"):
        law = 0.3 * (ox - ex - prm.p_m - RETURN_HEADWAY_S * evx) + 0.8 * (ov - evx)
    return np.where(np.isfinite(ox), law, np.inf)


def return_accel(ex, ey, evx, evy, ox, ov, prm: Params) -> tuple[np.ndarray, np.ndarray]:
    """The proposal of a returning vehicle (shield frame: its own lane's centre ``y = 0``): laterally a critically
    damped law to ``y = 0`` (natural frequency :data:`RETURN_OMEGA`); longitudinally it follows the own-lane leader
    ``L0`` (:func:`follow_l0`: back up to its lane's speed after the abort's braking, rather than crawling on at the
    speed the abort left it with), its speed kept where there is none. Clipped to the mechanical limits."""
    a_x = np.where(np.isfinite(ox), follow_l0(ex, evx, ox, ov, prm), 0.0)
    a_y = -(RETURN_OMEGA**2) * ey - 2.0 * RETURN_OMEGA * evy
    return np.clip(a_x, -prm.a_x_d, prm.a_x_a), np.clip(a_y, -prm.a_y_m, prm.a_y_m)


class LaneChanges:
    """The equipped vehicles' lane changes in one run; ``counts`` says what happened."""

    def __init__(self, world, params: Params, *, variant: str = "CV_all", wish_every_s: float = 0.5,
                 give_up_s: float = 15.0, settle_s: float = 6.0, cooldown_s: float = 2.0,
                 return_deadline_s: float = 8.0, resume_s: float = 0.0, l0_aware: bool = True,
                 brake_comfort: float = BRAKE_COMFORT, others: bool = False, others_window_m: float = OTHERS_WINDOW_M,
                 others_slots: int = OTHERS_SLOTS):  # fmt: skip
        self.world, self.params = world, params
        self.others, self.others_window_m, self.others_slots = others, others_window_m, others_slots
        self.l0_aware = l0_aware
        self.return_deadline_s, self.resume_s = return_deadline_s, resume_s
        self.pool = ShieldPool(params, variant)
        self.planner = ExpertPlanner(brake_comfort=brake_comfort)
        self.wish_every = max(1, round(wish_every_s / params.dt))
        self.give_up_s, self.settle_s, self.cooldown_s = give_up_s, settle_s, cooldown_s
        self.ids: list[str] = []
        z = np.zeros(0)
        self.g0, self.sign = np.zeros(0, np.int64), z.copy()
        self.ex, self.ey, self.evx, self.evy = (z.copy() for _ in range(4))
        self.t0, self.t_done, self.t_ret, self.t_abort = (z.copy() for _ in range(4))
        self.aborted, self.ret, self.late = np.zeros(0, bool), np.zeros(0, bool), np.zeros(0, bool)
        self.cool: dict[str, float] = {}
        self.counts = {"started": 0, "completed": 0, "aborted": 0, "gave_up": 0, "decisions": 0, "hesitate": 0,
                       "abort_steps": 0, "shield_calls": 0, "return_max_s": 0.0, "return_late": 0,
                       "others_slots": 0, "others_connected": 0, "others_announced": 0,
                       "left_network": 0}  # fmt: skip
        self.k = 0

    # -- one period -------------------------------------------------------------------------------------------------
    def period(self, fleet, t: float) -> None:
        index = {vid: i for i, vid in enumerate(fleet.ids)}
        self._fleet_ids = fleet.ids
        alive = np.array([vid in index for vid in self.ids], bool)
        keep = np.flatnonzero(alive)
        self._select(keep)
        new = self._starters(fleet, t, index) if self.k % self.wish_every == 0 else []
        self.k += 1
        n_new = len(new)
        if n_new:
            fi = np.array([index[v] for v in new])
            lane = fleet.lane[fi]
            direction = np.array(self._new_dirs)
            self.ids += list(new)
            self.g0 = np.concatenate([self.g0, lane])
            self.sign = np.concatenate([self.sign, direction.astype(float)])
            self.ex = np.concatenate([self.ex, fleet.x[fi]])
            self.ey = np.concatenate([self.ey, direction * (fleet.y[fi] - dem.lane_y(lane))])
            self.evx = np.concatenate([self.evx, fleet.v[fi]])
            self.evy = np.concatenate([self.evy, np.zeros(n_new)])
            self.t0 = np.concatenate([self.t0, np.full(n_new, t)])
            self.t_done = np.concatenate([self.t_done, np.full(n_new, np.nan)])
            self.t_ret = np.concatenate([self.t_ret, np.full(n_new, np.nan)])
            self.t_abort = np.concatenate([self.t_abort, np.full(n_new, np.nan)])
            self.aborted = np.concatenate([self.aborted, np.zeros(n_new, bool)])
            self.ret = np.concatenate([self.ret, np.zeros(n_new, bool)])
            self.late = np.concatenate([self.late, np.zeros(n_new, bool)])
            self.counts["started"] += n_new
            for vid in new:
                self.world.take(vid)
        if not self.ids:
            self.world.limit_braking([], [])
            return
        rows = np.array([index[v] for v in self.ids])
        x = fleet.x.copy()
        x[rows] = self.ex  # the changers at their exact states
        situation, chain_ids = self.situation(fleet, x, rows, t)
        completed_before = np.zeros(len(self.ids), bool)
        held = self.pool.shield.completed
        if held is not None and len(keep):
            completed_before[: len(keep)] = held[keep]
        proposal = self._proposal(situation, fleet, chain_ids, completed_before)
        d = decide(self.pool, situation, proposal, keep, n_new)
        self.counts["shield_calls"] = self.pool.calls
        self.counts["decisions"] += len(self.ids)
        self.counts["hesitate"] += int((d.behaviour == HESITATE).sum())
        self.counts["abort_steps"] += int((d.behaviour == ABORT).sum())
        # an abort from across the line (in the conflict zone) ends the attempt; one from inside the own lane is the
        # shield braking for one period (for L0, or before the vehicle has left its lane), as in the paper's world
        aborting = (d.behaviour == ABORT) & (situation.ego_y > self.params.y_safe)
        self.aborted |= aborting
        self.t_abort = np.where(aborting & np.isnan(self.t_abort), t, self.t_abort)
        self._move(d)
        self._cap_chains(situation, chain_ids, rows)
        self._finish(t)

    def _select(self, rows) -> None:
        self.ids = [self.ids[i] for i in rows]
        for name in ("g0", "sign", "ex", "ey", "evx", "evy", "t0", "t_done", "t_ret", "t_abort", "aborted", "ret",
                     "late"):  # fmt: skip
            setattr(self, name, getattr(self, name)[rows])

    def _starters(self, fleet, t, index) -> list[str]:
        changing = set(self.ids)
        cand = [vid for i, vid in enumerate(fleet.ids)
                if fleet.equipped[i] and vid not in changing and fleet.lane[i] >= 0 and self.cool.get(vid, -1e9) <= t
                and fleet.x[i] < dem.ACCEL_X[1] + 1000.0]  # fmt: skip
        wish = self.world.wishes(cand) if cand else np.zeros(0, np.int64)
        out, dirs = [], []
        for vid, w in zip(cand, wish.tolist(), strict=True):
            target = int(fleet.lane[index[vid]]) - w  # left (+1) is towards g = 0
            if w and 0 <= target < dem.ACCEL_LANE:  # never into the acceleration lane
                out.append(vid)
                dirs.append(w)
        self._new_dirs = dirs
        return out

    # -- the batch situation ---------------------------------------------------------------------------------------
    def situation(self, fleet, x, rows, t):
        """The changers' :class:`Situation` (shield frame: own lane ``y = 0``, target ``y = lane_width``) and the
        fleet index of each chain slot (``-1`` where padded). Built from the fleet's arrays for the whole batch at
        once (:func:`.lanes.neighbours`) and validated by the ``Shield.step`` it is for."""
        prm = self.params
        b, m = len(self.ids), CHAIN_SLOTS
        target = self.g0 - self.sign.astype(np.int64)
        # F: the nearest vehicle behind in the target lane, at the highest speed of the vehicles from it back to the
        # nearest one that stays in that lane. A changer still changing lanes is there only for now (it may abort and
        # leave, revealing the vehicle behind it, perhaps much faster): a vehicle at the nearest one's position and
        # the fastest one's speed is ahead of each of them at every instant (all accelerate alike in the aggressive
        # worst case), so keeping p_m to it keeps p_m to all of them.
        dest = np.where(self.ret, self.g0, target)
        settled = self.ret | ~np.isnan(self.t_done)
        lane_kept = np.full(len(fleet.ids), -2)  # the lane each changer stays in (-1: none yet); -2: not a changer
        lane_kept[rows] = np.where(settled, dest, -1)
        # the chain L1..L(M) ahead in the target lane; L0 the nearest ahead in the own lane, or the acceleration
        # lane's end (a standing obstacle, its rear bumper at the end) where that is nearer
        fx, fv, fcon, lx, lv, chain_ids, n_conn, ox, ov = neighbours(
            fleet, x, lane_kept, rows, target, self.g0, self.ex, self.evx, m, FAR_M,
            0.5 * (prm.lane_width + prm.vehicle_width) - 1e-6, dem.ACCEL_X[1] + 0.5 * prm.vehicle_length,
        )  # fmt: skip
        others = others_record(self, fleet, x, rows, t) if self.others else None
        situation = Situation(
            t=float(t), ego_x=self.ex.copy(), ego_y=self.ey.copy(), ego_vx=self.evx.copy(), ego_vy=self.evy.copy(),
            f_x=fx, f_v=fv, f_connected=fcon, f_collaborative=np.zeros(b, bool), chain_x=lx, chain_v=lv,
            chain_promise=np.full((b, m - 1), PROMISE_DECEL), chain_human=np.zeros((b, m - 1), bool),
            n_connected=n_conn, own_x=ox[:, None], own_v=ov[:, None], own_promise=np.zeros((b, 0)),
            own_n_connected=np.zeros(b, np.int64), others=others,
        )  # fmt: skip
        return situation, chain_ids

    def _proposal(self, s: Situation, fleet, chain_ids, completed) -> tuple[np.ndarray, np.ndarray]:
        """The expert's proposal for the changers; :func:`return_accel` for the returning ones. The expert knows
        only F and the chain (the paper's world); until the change completes its ``a_x`` is capped by
        :func:`follow_l0` (``l0_aware``), so that it does not close on its own lane's leader and leave the shield
        to brake for it."""
        a_x, a_y = self.planner(self._observation(s, fleet, chain_ids, completed), self.params)
        if self.l0_aware:
            cap = follow_l0(s.ego_x, s.ego_vx, s.own_x[:, 0], s.own_v[:, 0], self.params)
            a_x = np.where(completed, a_x, np.clip(np.minimum(a_x, cap), -self.params.a_x_d, self.params.a_x_a))
        if self.ret.any():
            r_x, r_y = return_accel(s.ego_x, s.ego_y, s.ego_vx, s.ego_vy, s.own_x[:, 0], s.own_v[:, 0], self.params)
            a_x, a_y = np.where(self.ret, r_x, a_x), np.where(self.ret, r_y, a_y)
        return a_x, a_y

    def _observation(self, s: Situation, fleet, chain_ids, completed) -> Observation:
        """What the expert sees. Where the target lane has no F behind (or no L1 ahead) the situation pads it
        ``FAR_M`` away; the expert, which steers into the middle of the F–L1 gap, would then brake (or accelerate)
        as hard as it can toward a point kilometres away. So the observation places a missing one symmetric to the
        other about the ego (the gap's middle at the ego: only the speed term acts), both ``FAR_M/2`` away where
        both are missing."""
        l1 = chain_ids[:, 0]
        l1_conn = s.n_connected > 0
        acc = np.where(l1_conn, fleet.a[np.maximum(l1, 0)], 0.0)
        has_l, has_f = l1 >= 0, s.f_x > s.ego_x - FAR_M + 1.0
        half = 0.5 * FAR_M
        p_l = np.where(has_l, s.chain_x[:, 0], np.where(has_f, 2.0 * s.ego_x - s.f_x, s.ego_x + half))
        p_f = np.where(has_f, s.f_x, np.where(has_l, 2.0 * s.ego_x - s.chain_x[:, 0], s.ego_x - half))
        return Observation(p_x=s.ego_x, p_y=s.ego_y, v_x=s.ego_vx, v_y=s.ego_vy, p_x_l=p_l,
                           v_x_l=s.chain_v[:, 0], p_x_f=p_f, v_x_f=s.f_v, l1_plan=np.repeat(acc[:, None], 10, 1),
                           l1_connected=l1_conn, f_connected=s.f_connected, completed=completed, t=s.t,
                           scenario_id=np.zeros(len(s), np.int64))  # fmt: skip

    # -- acting ---------------------------------------------------------------------------------------------------
    def _move(self, d) -> None:
        dt = self.params.dt
        nx, nv = advance(self.ex, self.evx, d.a_x, dt)
        ny, nvy = self.ey + self.evy * dt + 0.5 * d.a_y * dt * dt, self.evy + d.a_y * dt
        rows, _, px, vx, py, vy = d.abort_motion()
        if len(rows):
            nx[rows], nv[rows], ny[rows], nvy[rows] = px[:, -1], vx[:, -1], py[:, -1], vy[:, -1]
        self.ex, self.evx, self.ey, self.evy = nx, nv, ny, nvy
        done = self.pool.shield.completed
        self.t_done = np.where(done & np.isnan(self.t_done), self.world.time() + dt, self.t_done)
        self.ret &= ~done  # a change the shield completed (an abort that ended past the completion level) completes
        self.world.place(self.ids, self.ex, dem.lane_y(self.g0) + self.sign * self.ey, self.evx)

    def _start_return(self, rows, t: float) -> None:
        """The rows in ``rows`` (a mask) that are not completed and not yet returning start their return now."""
        new = rows & ~self.ret & np.isnan(self.t_done)
        self.ret |= new
        self.t_ret = np.where(new, t, self.t_ret)

    def _finish(self, t: float) -> None:
        w = self.params.lane_width
        done = ~np.isnan(self.t_done)
        settled = done & (((np.abs(self.ey - w) < SETTLED_Y_M) & (np.abs(self.evy) < SETTLED_VY))
                          | (t - self.t_done > self.settle_s))  # fmt: skip
        with np.errstate(invalid="ignore"):
            self._start_return(~done & (t - self.t_abort >= self.resume_s), t)  # aborted: return from now on
        self._start_return(~done & (t - self.t0 > self.give_up_s), t)  # given up: return from now on
        home = self.ret & (np.abs(self.ey) < SETTLED_Y_M) & (np.abs(self.evy) < SETTLED_VY)
        # at the network's end a changer is handed back to SUMO wherever it is, so that it leaves (placed by moveToXY
        # beyond the last lane's end it stayed there, and the vehicles behind it ran into it)
        gone = ~(settled | home) & (self.ex >= getattr(self.world, "end_x", np.inf) - self.params.vehicle_length)
        age = np.where(self.ret, t - self.t_ret, 0.0)  # how long each return has lasted so far (finished or not)
        if len(age):
            self.counts["return_max_s"] = max(self.counts["return_max_s"], float(age.max()))
        late = self.ret & ~self.late & (age > self.return_deadline_s)
        self.counts["return_late"] += int(late.sum())  # once per return, when its deadline passes
        self.late |= late
        returned = home & self.aborted
        gave_up = home & ~self.aborted
        out = np.flatnonzero(settled | home | gone)
        if not len(out):
            return
        self.counts["completed"] += int(settled.sum())
        self.counts["aborted"] += int(returned.sum())
        self.counts["gave_up"] += int(gave_up.sum())
        self.counts["left_network"] += int(gone.sum())
        put = np.flatnonzero(settled | home)
        y_end = np.where(settled, w, 0.0)[put]
        self.world.place([self.ids[i] for i in put], self.ex[put], dem.lane_y(self.g0[put]) + self.sign[put] * y_end,
                         self.evx[put])  # fmt: skip
        vids = [self.ids[i] for i in out]
        for vid in vids:
            self.world.release(vid)
            self.cool[vid] = t + self.cooldown_s
        stay = np.setdiff1d(np.arange(len(self.ids)), out)
        self._select(stay)
        self.pool.shield.regroup(stay)

    def _cap_chains(self, situation, chain_ids, rows) -> None:
        """Each equipped leader in a changer's connected chain (not itself changing lanes, ``rows``: the changers'
        fleet indices) brakes at most at ``max(promise, bound)`` in the next step, the smallest over its chains."""
        bounds, _ = chain_analysis(situation, self.params)
        m1 = chain_ids.shape[1] - 1
        slots = np.arange(m1)[None, :] < situation.n_connected[:, None]
        vid, bound = chain_ids[:, :m1][slots], bounds[:, :m1][slots]
        changer = np.zeros(len(self._fleet_ids), bool)
        changer[rows] = True
        vid, bound = vid[~changer[vid]], bound[~changer[vid]]
        caps = np.full(len(self._fleet_ids), np.inf)
        np.minimum.at(caps, vid, np.where(bound > PROMISE_DECEL, bound, PROMISE_DECEL))
        capped = np.flatnonzero(caps < np.inf)
        self.world.limit_braking([self._fleet_ids[i] for i in capped], caps[capped].tolist())
