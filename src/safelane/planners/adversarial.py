"""Adversarial nominal planners: proposals chosen to stress the safety supervisor, not to drive well.

The supervisor must keep *any* nominal planner safe (paper §3.1), so a falsifier feeds it planners that push
exactly where the worst case binds. Each is a plain :class:`~safelane.planners.base.NominalPlanner`
(``planner(obs, params) -> (a_x, a_y)``) built on the public interface only:

* :class:`HugLeader` — closes up to just behind ``L1`` (``p_m + offset_m``) at full authority;
* :class:`HugFollower` — drops back onto ``F`` (``p_m + offset_m`` ahead of it);
* :class:`Oscillating` — bang-bang longitudinal and lateral accelerations with a period and phases;
* :class:`RecklessMerge` — a constant longitudinal command and full lateral acceleration toward the target lane;
* :class:`Mixture` — one of the above per scenario (a ``(B,)`` choice), so one batch can hold all of them.

Every parameter is a scalar or a ``(B,)`` array aligned with the rows of the :class:`Observation` batch, so a
search can vary it per scenario. Rows are the simulator's batch rows: run such a batch with ``workers=1`` (a
batch split over worker processes would hand each worker a slice of the rows). Outputs are clipped to the
mechanical limits, like every planner's (the supervisor clips again and does not trust them).

Lateral law shared by the longitudinal adversaries: a damped PD toward the target-lane centre,
``a_y = ω² (w_l − p_y) − 2 ζ ω v_y``; a small damping ``ζ`` overshoots and swings back across the boundary.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, jitable
from .base import Observation, clip_actions


def _per_row(name: str, value, n: int) -> np.ndarray:
    """``value`` as a float ``(n,)`` array: a scalar is broadcast, an array must have exactly ``n`` rows."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(
            f"adversarial planner parameter {name} has shape {arr.shape}, but the observation batch has {n} rows "
            "(per-scenario parameters must be aligned with the batch; run with workers=1)"
        )
    return arr


def _lateral(obs: Observation, params: Params, omega, zeta):
    n = len(obs.p_y)
    return lateral_pd(ARRAY, params.lane_width, obs.p_y, obs.v_y, _per_row("omega", omega, n),
                      _per_row("zeta", zeta, n))  # fmt: skip


#: The shortest period of :class:`Oscillating`'s waves [s] (a period of 0 would divide by zero).
MIN_PERIOD_S = 1e-3


def lateral_pd(xp, lane_width, p_y, v_y, omega, zeta):
    """The longitudinal adversaries' lateral law: a damped PD toward the target-lane centre,
    ``ω² (w_l − p_y) − 2 ζ ω v_y`` (unclipped). Backend-generic, like every closed form below: the planners evaluate
    them on NumPy arrays, the compiled closed loop per row (``planners/_fast_adversary.py``)."""
    return omega * omega * (lane_width - p_y) - 2.0 * zeta * omega * v_y


def hug_accel(xp, target, p_x, v_ref, v_x, k_p, k_v):
    """:class:`HugLeader`'s and :class:`HugFollower`'s longitudinal law toward ``target`` at the speed ``v_ref``:
    ``k_p (target − p_x) + k_v (v_ref − v_x)`` (unclipped)."""
    return k_p * (target - p_x) + k_v * (v_ref - v_x)


def hug_leader_accel(xp, p_x, v_x, p_x_l, v_x_l, p_m, offset_m, k_p, k_v):
    """:class:`HugLeader`'s longitudinal law: to ``p_m + offset_m`` behind L1 at L1's speed (unclipped)."""
    return hug_accel(xp, p_x_l - p_m - offset_m, p_x, v_x_l, v_x, k_p, k_v)


def hug_follower_accel(xp, p_x, v_x, p_x_f, v_x_f, p_m, offset_m, k_p, k_v):
    """:class:`HugFollower`'s longitudinal law: to ``p_m + offset_m`` ahead of F at F's speed (unclipped)."""
    return hug_accel(xp, p_x_f + p_m + offset_m, p_x, v_x_f, v_x, k_p, k_v)


def oscillating_accel(xp, t, period_s, phase_x, phase_y, amp_x, mean_x, amp_y, mean_y):
    """:class:`Oscillating`'s ``(a_x, a_y)`` at time ``t`` (unclipped)."""
    period = xp.maximum(period_s, MIN_PERIOD_S)
    a_x = mean_x + amp_x * wave_level(xp, t, period, phase_x, 1.0, -1.0)
    a_y = mean_y + amp_y * wave_level(xp, t, period, phase_y, 1.0, -1.0)
    return a_x, a_y


def reckless_lateral(xp, lateral_gain, a_y_m, lane_width, p_y):
    """:class:`RecklessMerge`'s lateral command: ``lateral_gain · a_y_m`` toward the target-lane centre (0 on it)."""
    side = lane_width - p_y
    return lateral_gain * a_y_m * xp.where(side > 0.0, 1.0, xp.where(side < 0.0, -1.0, 0.0))


def wave_level(xp, t, period, phase, high, low):
    """A square wave between two levels at time ``t``: ``high`` on the first half of each ``period``, ``low`` on the
    second; ``phase`` in periods (``[0, 1)``). Backend-generic: the adversarial planners' waves (:func:`square_wave`)
    and the falsifier's traffic hooks as data (``sim/traffic.WaveHooks``, compiled in the closed loop)."""
    return xp.where((t / period + phase) % 1.0 < 0.5, high, low)


def square_wave(t: float, period_s, phase) -> np.ndarray:
    """``+1`` on the first half of each period, ``−1`` on the second; ``phase`` in periods (``[0, 1)``)."""
    return wave_level(ARRAY, t, np.asarray(period_s, float), np.asarray(phase, float), 1.0, -1.0)


@dataclass(frozen=True)
class HugLeader:
    """Close up to ``p_m + offset_m`` behind L1 at L1's speed, at full authority (high gains, clipped).

    Attributes (scalars or ``(B,)``): ``k_p`` [1/s²], ``k_v`` [1/s] — gains on the gap and speed errors;
    ``offset_m`` — target distance beyond ``p_m`` (0: aim exactly at the margin; negative: aim inside it);
    ``omega`` [rad/s], ``zeta`` — the lateral PD.
    """

    k_p: object = 2.0
    k_v: object = 3.0
    offset_m: object = 0.0
    omega: object = 0.8
    zeta: object = 1.0

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        n = len(obs.p_x)
        offset, k_p, k_v = (_per_row(name, getattr(self, name), n) for name in ("offset_m", "k_p", "k_v"))
        a_x = hug_leader_accel(ARRAY, obs.p_x, obs.v_x, obs.p_x_l, obs.v_x_l, params.p_m, offset, k_p, k_v)
        return clip_actions(a_x, _lateral(obs, params, self.omega, self.zeta), params)


@dataclass(frozen=True)
class HugFollower:
    """Drop back to ``p_m + offset_m`` ahead of F at F's speed (same attributes as :class:`HugLeader`)."""

    k_p: object = 2.0
    k_v: object = 3.0
    offset_m: object = 0.0
    omega: object = 0.8
    zeta: object = 1.0

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        n = len(obs.p_x)
        offset, k_p, k_v = (_per_row(name, getattr(self, name), n) for name in ("offset_m", "k_p", "k_v"))
        a_x = hug_follower_accel(ARRAY, obs.p_x, obs.v_x, obs.p_x_f, obs.v_x_f, params.p_m, offset, k_p, k_v)
        return clip_actions(a_x, _lateral(obs, params, self.omega, self.zeta), params)


#: :class:`Oscillating`'s parameters in :func:`oscillating_accel`'s order.
OSCILLATING = ("period_s", "phase_x", "phase_y", "amp_x", "mean_x", "amp_y", "mean_y")


@dataclass(frozen=True)
class Oscillating:
    """Bang-bang: ``a_x = mean_x + amp_x · sq(t)``, ``a_y = mean_y + amp_y · sq(t + phase_y)``.

    ``sq`` is :func:`square_wave` with ``period_s`` and the phases (in periods); amplitudes and means in m/s²
    (clipped to the limits afterwards). Periods near ``dt`` switch every control period; a period that is not a
    multiple of ``dt`` moves the switches across the period boundaries.
    """

    period_s: object = 1.0
    phase_x: object = 0.0
    phase_y: object = 0.25
    amp_x: object = 8.0
    mean_x: object = 0.0
    amp_y: object = 1.5
    mean_y: object = 0.5

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        n = len(obs.p_x)
        q = [_per_row(name, getattr(self, name), n) for name in OSCILLATING]
        return clip_actions(*oscillating_accel(ARRAY, obs.t, *q), params)


@dataclass(frozen=True)
class RecklessMerge:
    """Constant ``a_x`` and full lateral acceleration toward the target-lane centre (no damping: it overshoots
    and swings back, so it crosses the boundary again and again)."""

    a_x: object = 2.5
    lateral_gain: object = 1.0  # fraction of a_y_m

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        n = len(obs.p_x)
        a_y = reckless_lateral(ARRAY, _per_row("lateral_gain", self.lateral_gain, n), params.a_y_m, params.lane_width,
                               obs.p_y)  # fmt: skip
        return clip_actions(_per_row("a_x", self.a_x, n), a_y, params)


@dataclass(frozen=True)
class Mixture:
    """One planner per scenario: row ``b`` takes ``planners[choice[b]]``'s proposal (every planner is evaluated
    on the whole batch, which keeps per-row parameters aligned)."""

    planners: tuple
    choice: object

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        n = len(obs.p_x)
        choice = np.asarray(self.choice)
        if choice.shape != (n,):
            raise ValueError(f"Mixture.choice has shape {choice.shape}; the observation batch has {n} rows")
        a_x, a_y = np.zeros(n), np.zeros(n)
        for i, planner in enumerate(self.planners):
            rows = choice == i
            if rows.any():
                px, py = planner(obs, params)
                a_x = np.where(rows, px, a_x)
                a_y = np.where(rows, py, a_y)
        return a_x, a_y


#: Each adversary's kind in the compiled loop (``planner_kind``: :func:`adversary_table`) and its parameters in the
#: order of the table's columns; ``ZERO``: a :class:`Mixture` row whose choice names none of its planners (0, 0).
KINDS = {HugLeader: 0, HugFollower: 1, Oscillating: 2, RecklessMerge: 3}
ZERO = 4
COLUMNS = {
    HugLeader: ("k_p", "k_v", "offset_m", "omega", "zeta"), HugFollower: ("k_p", "k_v", "offset_m", "omega", "zeta"),
    Oscillating: OSCILLATING, RecklessMerge: ("a_x", "lateral_gain"),
}  # fmt: skip


def adversary_table(planner, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The planner as data for the compiled closed loop: ``(kind (n,) int64, q (n, 7))``, each row's adversary
    (:data:`KINDS`) and its parameters (:data:`COLUMNS`' order); ``None`` unless ``planner`` is one of the four
    adversaries or a :class:`Mixture` of them. Every parameter is checked as calling the planner checks it."""
    if type(planner) in KINDS:
        planners, choice = (planner,), np.zeros(n, np.int64)
    elif type(planner) is Mixture and all(type(p) in KINDS for p in planner.planners):
        planners, choice = planner.planners, np.asarray(planner.choice)
        if choice.shape != (n,):
            raise ValueError(f"Mixture.choice has shape {choice.shape}; the observation batch has {n} rows")
    else:
        return None
    kind, q = np.full(n, ZERO, np.int64), np.zeros((n, max(map(len, COLUMNS.values()))))
    for i, p in enumerate(planners):
        values = [_per_row(name, getattr(p, name), n) for name in COLUMNS[type(p)]]
        rows = choice == i
        kind[rows] = KINDS[type(p)]
        for j, value in enumerate(values):
            q[rows, j] = value[rows]
    return kind, q


#: The adversaries by name, in :class:`Mixture` order as the falsifier uses them.
ADVERSARIES = {
    "hug_leader": HugLeader,
    "hug_follower": HugFollower,
    "oscillating": Oscillating,
    "reckless": RecklessMerge,
}


jitable(wave_level, lateral_pd, hug_accel, hug_leader_accel, hug_follower_accel, oscillating_accel, reckless_lateral)
