"""Public extension points for the target-lane traffic.

The simulator asks a :class:`TrafficModel` every period for the target-lane vehicles' accelerations (the world
side; the ego's side is the shield). The built-in one, :class:`PaperTraffic`, is the paper's behaviours
(:mod:`safelane.sim.behaviours`); models are registered by name in :data:`TRAFFIC_MODELS` and passed as
``simulate(..., traffic=...)`` / ``simulate_batch(..., traffic=...)`` — a name, a model, or :class:`TrafficHooks`
(the paper's model with some wishes replaced). A whole new model implements ``bind(batch, seed, params, config)``
returning ``step(view) -> (acc, switch)`` (see :class:`TrafficModel`); it is then responsible for staying inside
the assumptions itself. The lighter way, for behaviours *inside* the assumptions without subclassing anything:

* :class:`TrafficHooks` — callables the closed loop asks every period for what a vehicle *wants* to do. The
  simulator then enforces the assumptions the guarantee rests on: a connected leader's wish is clipped into its
  promise ``[−a_m_d, a_m_a]`` and then to what keeps it safe against the vehicle ahead's worst case (it may
  brake beyond its promise only as far as the chain analysis allows); F's wish is clipped into the mechanical
  limits ``[−a_x_d, a_x_a]`` and filtered by responsible following (of L1, and of the ego as
  :class:`TrafficHooks` says). A hook therefore cannot leave the assumptions by accident.
* :func:`with_last_profile` — the braking profile of ``L(N+1)`` (the non-connected head of the chain): piecewise
  constant accelerations inside ``[−a_x_d, a_x_a]`` that may switch at any instant, also inside a control
  period (at most one switch per period).

Both are passed to :func:`safelane.sim.simulate_batch` (``traffic=``, and the batch itself).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, INF, jitable
from ..tolerances import SETTING_SLACK, TIME_TOL_S


@dataclass(frozen=True)
class TrafficView:
    """What a traffic hook sees at the start of a period (read-only arrays; the batch on the leading axis).

    Attributes:
        t: time [s] at the start of the period.
        scenario_id: ``(B,)`` stable scenario ids (index per-scenario parameters with them: a batch may be split
            over worker processes, so row numbers are not stable, ids are).
        x, v: ``(B, K)`` positions and speeds of the target-lane vehicles (slot 0 = F, 1..N the connected leaders,
            N+1 = L(N+1), padding beyond).
        n_connected: ``(B,)`` N.
        ego_x, ego_y, ego_vx, ego_vy: ``(B,)`` the ego's state.
        completed: ``(B,)`` the lane change has completed.
        follower_aggressive: ``(B,)`` F's true type.
        step: the period's index.
        bounds: ``(B, K)`` each vehicle's worst-case deceleration from the chain analysis (the smallest it has had;
            ``a_x_d`` for F's slot, ``L(N+1)`` and anything not connected) — what leaders must honour.
    """

    t: float
    scenario_id: np.ndarray
    x: np.ndarray
    v: np.ndarray
    n_connected: np.ndarray
    ego_x: np.ndarray
    ego_y: np.ndarray
    ego_vx: np.ndarray
    ego_vy: np.ndarray
    completed: np.ndarray
    follower_aggressive: np.ndarray
    step: int = 0
    bounds: np.ndarray | None = None


#: ``hook(view, params) -> (B, K)`` wanted accelerations [m/s²] of the connected leaders (other slots ignored).
LeaderTask = Callable[[TrafficView, Params], np.ndarray]
#: ``hook(view, params) -> (B,)`` wanted acceleration [m/s²] of F.
FollowerWish = Callable[[TrafficView, Params], np.ndarray]


@dataclass(frozen=True)
class TrafficHooks:
    """Behaviour hooks; ``None`` keeps the built-in behaviour.

    Attributes:
        leader_task: each connected leader's *own driving task* (built-in: hold the initial speed). Clipped into the
            promise, then made safe against the vehicle ahead's worst case (see the module docstring).
        follower_wish: F's wanted acceleration (built-in: collaborative opens a gap, then matches the ego's speed;
            aggressive closes on L1). Clipped into ``[−a_x_d, a_x_a]``, then filtered by responsible following: of
            L1 always, and of the ego whenever the ego is ahead of F and F is collaborative (an aggressive F once
            the lane change has completed). A collaborative F's wish is *not* clipped to ``<= 0``: it may accelerate
            behind a lane-changing ego, as far as keeping ``p_m`` to the ego against the ego braking at ``a_x_d``
            allows — "collaborative" means it yields responsibly, which is what the shield assumes of it and its
            assumption monitor watches (``tests/test_validation_traffic.py`` pins this).
    """

    leader_task: LeaderTask | None = None
    follower_wish: FollowerWish | None = None


def hook_output(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """A hook's answer as a finite float array of ``shape``, or a ``ValueError`` naming the hook."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"traffic hook {name} must return numbers of shape {shape}; got {type(value).__name__}"
        ) from exc
    if arr.shape != shape:
        raise ValueError(f"traffic hook {name} must return shape {shape}; got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"traffic hook {name} returned a non-finite value {arr[~np.isfinite(arr)].flat[0]!r}")
    return arr


def with_last_profile(batch, switch_times_s, accels_mps2, params: Params | None = None):
    """``batch`` with L(N+1) driving a piecewise-constant acceleration profile instead of the sudden braking.

    Args:
        batch: a :class:`~safelane.sim.ScenarioBatch`.
        switch_times_s: ``(B, P)`` ascending times [s] at which segment ``j`` starts; ``[:, 0]`` must be 0. Pad
            unused segments by repeating the last time (zero-length segments are ignored).
        accels_mps2: ``(B, P)`` acceleration of each segment, inside ``[−a_o_d, a_x_a]`` (the others' maximum
            braking ``a_o_d``, ``a_x_d`` unless set; beyond it leaves the assumptions: it is rejected here; use
            ``decel_last`` for that study).
        params: the limits to check against (default ``Params()``).

    Consecutive switches must be at least one control period apart apart from padding (at most one switch
    inside any period); the simulator integrates the switch exactly.
    """
    prm = params or Params()
    t = np.asarray(switch_times_s, dtype=float)
    a = np.asarray(accels_mps2, dtype=float)
    n = len(batch)
    if t.ndim != 2 or t.shape[0] != n or a.shape != t.shape:
        raise ValueError(f"switch_times_s and accels_mps2 must both have shape ({n}, P); got {t.shape} and {a.shape}")
    if not (np.isfinite(t).all() and np.isfinite(a).all()):
        raise ValueError("switch_times_s and accels_mps2 must be finite")
    if (t[:, 0] != 0.0).any():
        raise ValueError(f"switch_times_s[:, 0] must be 0 (the profile starts at t = 0); got {t[t[:, 0] != 0, 0][0]!r}")
    steps = np.diff(t, axis=1)
    if (steps < 0).any():
        raise ValueError("switch_times_s must be ascending along each row")
    if ((steps > 0) & (steps < prm.dt - SETTING_SLACK)).any():
        raise ValueError(f"switches must be at least one period (dt={prm.dt} s) apart (at most one per period)")
    brake = prm.others_decel  # L(N+1) is one of the others: it brakes up to their maximum a_o_d (a_x_d unless set)
    if (a < -brake - SETTING_SLACK).any() or (a > prm.a_x_a + SETTING_SLACK).any():
        bad = a[(a < -brake - SETTING_SLACK) | (a > prm.a_x_a + SETTING_SLACK)].flat[0]
        raise ValueError(f"accels_mps2 must lie in [-a_o_d={-brake}, a_x_a={prm.a_x_a}] (a_o_d: Params.others_decel); "
                         f"got {bad!r}")  # fmt: skip
    return dataclasses.replace(batch, last_profile_t=t, last_profile_a=a)


def profile_segment(t_start: float, dt: float, times: np.ndarray, accels: np.ndarray):
    """The profile over the period ``[t_start, t_start + dt]``: ``(a1, t_switch, a2)`` per row, ``t_switch``
    relative to the period's start (``dt`` and ``a2 = a1`` where nothing switches inside it). A scan of the
    segments (:func:`profile_scan`, :func:`profile_after`, :func:`profile_end`), the compiled loop's too."""
    now = t_start + TIME_TOL_S
    a1, t_next = accels[:, 0], np.full(len(times), np.inf)
    for j in range(times.shape[1]):
        a1, t_next = profile_scan(ARRAY, now, times[:, j], accels[:, j], a1, t_next)
    a2 = a1
    for j in range(times.shape[1]):
        a2 = profile_after(ARRAY, t_next, times[:, j], accels[:, j], a2)
    return profile_end(ARRAY, t_start, dt, TIME_TOL_S, a1, t_next, a2)


def profile_scan(xp, now, t_j, a_j, a1, t_next):
    """Segment ``j`` (starts ascending, from ``j = 0``) of :func:`profile_segment`'s scan: ``a1`` the acceleration of
    the last segment started by ``now`` (the period's start plus the time tolerance; padding repeats a start),
    ``t_next`` the first start after ``now`` (``inf`` while none is seen). Backend-generic."""
    later = t_j > now
    return xp.where(later, a1, a_j), xp.where(later & (t_next == INF), t_j, t_next)


def profile_after(xp, t_next, t_j, a_j, a2):
    """Segment ``j`` of the second scan: ``a2`` the acceleration of the last segment that starts at ``t_next``.
    Backend-generic."""
    return xp.where(t_j <= t_next, a_j, a2)


def profile_end(xp, t_start, dt, eps, a1, t_next, a2):
    """``(a1, t_switch, a2)`` of the period from the scans: a switch where the next start lies inside the period
    (by more than ``eps`` before its end). Backend-generic."""
    inside = t_next < t_start + dt - eps
    return a1, xp.where(inside, t_next - t_start, dt), xp.where(inside, a2, a1)


@dataclass(frozen=True, eq=False)
class WaveHooks(TrafficHooks):
    """:class:`TrafficHooks` as data: square waves between two levels
    (:func:`~safelane.planners.adversarial.wave_level`), per scenario id, which the compiled closed loop reads as the
    NumPy path calls them (the falsifier's hooks: ``experiments/falsify_build.hooks_for``).

    Attributes (first axis the scenario id):
        task_low, task_span, task_hi, task_lo, task_phase: ``(S, K)`` each leader's wish
            ``task_low + level · task_span``, ``level`` ``task_hi`` on the first half of its wave, ``task_lo`` on the
            second, its phase in periods;
        task_period: ``(S,)`` the leaders' wave period [s];
        f_period, f_phase, f_hi, f_lo: ``(S,)`` F's wave: ``−a_x_d + level · (a_x_d + a_x_a)``;
        lane_valid, lane_margin, lane_ratio: ``(S, K−1)``, ``(S, K−1)``, ``(S,)`` or ``None``: the running minimum,
            sampled at the start of every period, of each scenario's consecutive target-lane gaps over their margins
            (:func:`~.behaviours.gap_ratio`), written into ``lane_ratio`` (where it is not ``None``).
    """

    task_low: np.ndarray | None = None
    task_span: np.ndarray | None = None
    task_hi: np.ndarray | None = None
    task_lo: np.ndarray | None = None
    task_phase: np.ndarray | None = None
    task_period: np.ndarray | None = None
    f_period: np.ndarray | None = None
    f_phase: np.ndarray | None = None
    f_hi: np.ndarray | None = None
    f_lo: np.ndarray | None = None
    lane_valid: np.ndarray | None = None
    lane_margin: np.ndarray | None = None
    lane_ratio: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "leader_task", self._leader_task)
        object.__setattr__(self, "follower_wish", self._follower_wish)

    def _leader_task(self, view: TrafficView, params: Params) -> np.ndarray:
        from .behaviours import gap_ratio, wave_level, wave_wish

        ids = view.scenario_id
        if self.lane_ratio is not None:
            ratio = gap_ratio(ARRAY, self.lane_valid[ids], view.x[:, :-1], view.x[:, 1:], self.lane_margin[ids])
            self.lane_ratio[ids] = np.minimum(self.lane_ratio[ids], ratio.min(1))
        level = wave_level(ARRAY, view.t, self.task_period[ids][:, None], self.task_phase[ids], self.task_hi[ids],
                           self.task_lo[ids])  # fmt: skip
        return wave_wish(ARRAY, level, self.task_low[ids], self.task_span[ids])

    def _follower_wish(self, view: TrafficView, params: Params) -> np.ndarray:
        from .behaviours import wave_level, wave_wish

        ids = view.scenario_id
        level = wave_level(ARRAY, view.t, self.f_period[ids], self.f_phase[ids], self.f_hi[ids], self.f_lo[ids])
        return wave_wish(ARRAY, level, -params.a_x_d, params.a_x_d + params.a_x_a)


@runtime_checkable
class TrafficModel(Protocol):
    """The target-lane vehicles' behaviour. ``bind`` is called once per run with the scenario batch, the seed, the
    parameters and the :class:`~safelane.sim.SimConfig`; it returns ``step(view) -> (acc, switch)``, called every
    period with a :class:`TrafficView`: ``acc`` ``(B, K)`` accelerations for the period (slot 0 is F), ``switch``
    ``None`` or ``(t_switch (B, K), a2 (B, K))`` for vehicles whose acceleration changes to ``a2`` inside the period
    (``t_switch = dt`` elsewhere)."""

    def bind(self, batch, seed: int, params: Params, config) -> Callable[[TrafficView], tuple]: ...


@dataclass(frozen=True)
class PaperTraffic:
    """The paper's traffic (docs/simulator.md, "Behaviours"): L(N+1)'s sudden braking or profile, connected leaders
    by ``leader_rule`` (``None``: ``SimConfig.leader_rule``), F collaborative or aggressive as a responsible
    follower; ``hooks`` replace the leaders' own tasks and F's wish."""

    hooks: TrafficHooks = TrafficHooks()
    leader_rule: str | None = None

    def bind(self, batch, seed: int, params: Params, config):
        from ._paper_traffic import BoundPaperTraffic

        return BoundPaperTraffic(batch, seed, params, config, self.hooks, self.leader_rule or config.leader_rule)


#: Registered traffic models (``traffic="name"``).
TRAFFIC_MODELS: dict[str, TrafficModel] = {
    "paper": PaperTraffic(),
    "paper_worst_case": PaperTraffic(leader_rule="worst_case"),
    "paper_reactive": PaperTraffic(leader_rule="reactive"),
}


def resolve_traffic(traffic) -> TrafficModel:
    """A :class:`TrafficModel` from ``None`` (the paper's), a registered name, :class:`TrafficHooks` or a model."""
    if traffic is None:
        return TRAFFIC_MODELS["paper"]
    if isinstance(traffic, str):
        if traffic not in TRAFFIC_MODELS:
            raise ValueError(f"unknown traffic model {traffic!r}; choose one of {', '.join(TRAFFIC_MODELS)}")
        return TRAFFIC_MODELS[traffic]
    if isinstance(traffic, TrafficHooks):
        return PaperTraffic(hooks=traffic)
    if isinstance(traffic, TrafficModel):
        return traffic
    raise TypeError(
        f"traffic must be a registered name ({', '.join(TRAFFIC_MODELS)}), TrafficHooks or a TrafficModel; got "
        f"{type(traffic).__name__}"
    )


# The profile's scan, compiled into the closed loop (safety/_compile.py, through _fast_loop): the same functions, row by
# row.
jitable(profile_scan, profile_after, profile_end)
