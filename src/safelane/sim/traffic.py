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
    relative to the period's start (``dt`` and ``a2 = a1`` where nothing switches inside it)."""
    eps = TIME_TOL_S
    idx = (times <= t_start + eps).sum(1) - 1  # the last segment started by now (padding repeats a start)
    rows = np.arange(len(times))
    a1 = accels[rows, idx]
    later = times > t_start + eps
    has_later = later.any(1)
    t_next = np.where(has_later, times[rows, np.argmax(later, 1)], np.inf)
    last_at = (times <= t_next[:, None]).sum(1) - 1  # the segment that starts at t_next
    inside = t_next < t_start + dt - eps
    a2 = np.where(inside, accels[rows, np.minimum(last_at, times.shape[1] - 1)], a1)
    t_sw = np.where(inside, t_next - t_start, dt)
    return a1, t_sw, a2


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
