"""Traffic and V2X for :mod:`safelane.integrations.sumo`: who drives the target-lane vehicles, and what reaches the
ego over V2X.

* ``traffic="paper"``: the target-lane vehicles follow safelane's models (:mod:`safelane.sim.behaviours`, the
  guarantee's ``worst_case`` leader rule) computed in Python from SUMO's states and commanded as speeds; SUMO
  integrates and referees. Connected leaders honour the bounds the chain analysis gives them; F is a responsible
  follower (collaborative, or aggressive until the lane change completes) — the shield's assumptions.
* ``traffic="sumo"``: F and the connected leaders are SUMO's own drivers (Krauss, ``sigma = 0``, decel ``a_x_d``,
  keeping their initial speed); they never promised anything, so their promise violations are measured
  (:attr:`TargetLaneTraffic.violations`), not assumed away.

In both, ``L(N+1)``'s sudden braking and the own-lane leader ``L0``'s profile are injected explicitly (speed
commands, speed mode 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import v2x
from ..params import Params
from ..safety._backend import ARRAY
from ..safety.chain import propagate_chain
from ..sim.behaviours import follower_accel, leader_accels, leader_roles, leader_task
from ..tolerances import TIME_TOL_S

TRAFFIC_MODES = ("paper", "sumo")
VIOLATION_TOL_MPS2 = 1e-6


@dataclass
class TargetLaneTraffic:
    """The target lane's vehicles as slots ``[F, L1, …, L(N+1)]`` (the simulator's layout, batch of one).

    ``step(t, x, v, ego_x, ego_vx, completed)`` gives this period's accelerations (``nan`` for a vehicle SUMO drives
    itself); ``observe(x_old, v_old, v_new)`` checks the connected leaders against their bounds afterwards.
    """

    params: Params
    mode: str
    n_connected: int
    promise_decel: float
    promise_accel: float
    f_aggressive: bool
    decel_last: float
    brake_start_s: float
    v_desired: np.ndarray  # (K,)
    gap0: float
    open_decel: float = 0.5
    open_gap_m: float = 3.0

    def __post_init__(self):
        if self.mode not in TRAFFIC_MODES:
            raise ValueError(f"traffic must be one of {TRAFFIC_MODES}; got {self.mode!r}")
        k = len(self.v_desired)
        slots = np.arange(k)
        self.connected = ((slots >= 1) & (slots <= self.n_connected))[None, :]
        self.valid = np.ones((1, k), bool)
        self.roles = leader_roles(self.valid, self.connected, np.array([self.n_connected]))
        self.margin = np.full((1, k), self.params.p_m)
        self.promise = np.full((1, k), self.promise_decel)
        self.chain_promise = np.full((k - 2, 1), self.promise_decel)
        self.chain_margin = np.full((k - 2, 1), self.params.p_m)
        self.cap = np.full((1, k), np.inf)  # running minimum of the bounds (they never grow: docs/simulator.md)
        self.bounds = np.full((1, k), self.params.a_x_d)
        self.violations = 0
        self.max_violation_mps2 = 0.0

    @property
    def sumo_driven(self) -> tuple[int, ...]:
        """Slots SUMO drives itself (``traffic="sumo"``: F and the connected leaders)."""
        if self.mode == "paper":
            return ()
        return (0, *range(1, self.n_connected + 1))

    def chain_bounds(self, x, v) -> np.ndarray:
        """``(1, K)`` each slot's worst-case deceleration on the true states (``a_x_d`` for F and ``L(N+1)``)."""
        prm = self.params
        k = x.shape[1]
        with np.errstate(all="ignore"):
            decel, _, _ = propagate_chain(ARRAY, x.T[1:], v.T[1:], self.chain_promise, self.chain_margin, prm, k - 2)
        bounds = np.column_stack([np.full(1, prm.a_x_d), *(np.broadcast_to(d, (1,)) for d in decel)])
        self.cap = np.minimum(self.cap, bounds)
        self.bounds = self.cap
        return self.cap

    def step(self, t: float, x, v, ego_x: float, ego_vx: float, completed: bool) -> np.ndarray:
        prm = self.params
        x, v = np.asarray(x, float)[None, :], np.asarray(v, float)[None, :]
        bounds = self.chain_bounds(x, v)
        a_last = np.array([-self.decel_last if t + TIME_TOL_S >= self.brake_start_s else 0.0])
        task = leader_task(v, self.v_desired[None, :], self.promise, np.full_like(self.promise, self.promise_accel))
        acc = np.array(leader_accels(x, v, self.margin, self.roles, bounds, task, a_last, np.array([self.decel_last]),
                                     None, None, prm))  # fmt: skip
        acc[:, 0] = follower_accel(
            x[:, 0], v[:, 0], x[:, 1], v[:, 1], np.array([ego_x]), np.array([ego_vx]), np.array([self.f_aggressive]),
            np.array([completed]), np.array([self.gap0]), prm, self.open_decel, self.open_gap_m,
        )  # fmt: skip
        out = acc[0]
        for slot in self.sumo_driven:
            out[slot] = np.nan
        return out

    def observe(self, v_old, v_new) -> None:
        """Count the connected leaders that braked beyond ``max(promise, bound)`` over the last period."""
        dt = self.params.dt
        for i in range(1, self.n_connected + 1):
            if v_new[i] <= 0.0:  # stopped: the speed change understates nothing
                continue
            decel = (v_old[i] - v_new[i]) / dt
            allowed = max(self.promise_decel, float(self.bounds[0, i]))
            if decel > allowed + VIOLATION_TOL_MPS2:
                self.violations += 1
                self.max_violation_mps2 = max(self.max_violation_mps2, decel - allowed)


def profile_accel(t: float, brake_start_s: float, decel: float) -> float:
    """A sudden-braking profile: constant speed, then ``−decel`` from ``brake_start_s`` until the vehicle stops."""
    return -decel if t + TIME_TOL_S >= brake_start_s else 0.0


@dataclass
class V2XLink:
    """V2X emulation through :mod:`safelane.v2x` messages: each connected vehicle broadcasts every period; a message
    is lost with probability ``loss`` and arrives ``latency_periods`` periods late; the ego keeps the latest message
    it received from each sender (older than ``max_age_s``: stale, the sender counts as non-connected)."""

    params: Params
    loss: float = 0.0
    latency_periods: int = 0
    max_age_s: float = v2x.MAX_AGE_S
    seed: int = 0

    def __post_init__(self):
        if not 0.0 <= self.loss < 1.0:
            raise ValueError(f"V2X loss must lie in [0, 1); got {self.loss!r}")
        if self.latency_periods < 0:
            raise ValueError(f"V2X latency_periods must be >= 0; got {self.latency_periods!r}")
        self.rng = np.random.default_rng(self.seed)
        self.in_flight: list[tuple[int, v2x.V2XMessage]] = []
        self.latest: dict[str, v2x.V2XMessage] = {}
        self.sent = self.lost = 0

    def broadcast(self, step: int, messages: list[v2x.V2XMessage]) -> None:
        for msg in messages:
            self.sent += 1
            if self.loss and self.rng.uniform() < self.loss:
                self.lost += 1
                continue
            self.in_flight.append((step + self.latency_periods, msg))

    def receive(self, step: int) -> None:
        keep = []
        for due, msg in self.in_flight:
            if due <= step:
                old = self.latest.get(msg.vehicle_id)
                if old is None or msg.timestamp_s > old.timestamp_s:
                    self.latest[msg.vehicle_id] = msg
            else:
                keep.append((due, msg))
        self.in_flight = keep

    def message(self, vid: str) -> v2x.V2XMessage | None:
        return self.latest.get(vid)
