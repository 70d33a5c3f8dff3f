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
    w, z = _per_row("omega", omega, n), _per_row("zeta", zeta, n)
    return w * w * (params.lane_width - obs.p_y) - 2.0 * z * w * obs.v_y


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
        target = obs.p_x_l - params.p_m - _per_row("offset_m", self.offset_m, n)
        a_x = _per_row("k_p", self.k_p, n) * (target - obs.p_x) + _per_row("k_v", self.k_v, n) * (obs.v_x_l - obs.v_x)
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
        target = obs.p_x_f + params.p_m + _per_row("offset_m", self.offset_m, n)
        a_x = _per_row("k_p", self.k_p, n) * (target - obs.p_x) + _per_row("k_v", self.k_v, n) * (obs.v_x_f - obs.v_x)
        return clip_actions(a_x, _lateral(obs, params, self.omega, self.zeta), params)


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
        n, t = len(obs.p_x), obs.t
        period = np.maximum(_per_row("period_s", self.period_s, n), 1e-3)
        sq_x = square_wave(t, period, _per_row("phase_x", self.phase_x, n))
        sq_y = square_wave(t, period, _per_row("phase_y", self.phase_y, n))
        a_x = _per_row("mean_x", self.mean_x, n) + _per_row("amp_x", self.amp_x, n) * sq_x
        a_y = _per_row("mean_y", self.mean_y, n) + _per_row("amp_y", self.amp_y, n) * sq_y
        return clip_actions(a_x, a_y, params)


@dataclass(frozen=True)
class RecklessMerge:
    """Constant ``a_x`` and full lateral acceleration toward the target-lane centre (no damping: it overshoots
    and swings back, so it crosses the boundary again and again)."""

    a_x: object = 2.5
    lateral_gain: object = 1.0  # fraction of a_y_m

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        n = len(obs.p_x)
        a_y = _per_row("lateral_gain", self.lateral_gain, n) * params.a_y_m * np.sign(params.lane_width - obs.p_y)
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


#: The adversaries by name, in :class:`Mixture` order as the falsifier uses them.
ADVERSARIES = {
    "hug_leader": HugLeader,
    "hug_follower": HugFollower,
    "oscillating": Oscillating,
    "reckless": RecklessMerge,
}


jitable(wave_level)
