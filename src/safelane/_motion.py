"""Exact one-segment motion at constant acceleration, stopping at rest (speed never goes negative), and the maximum
of a free (non-stopping) one.

NumPy only, so that :mod:`safelane.v2x` (imported with the package) and the simulator (:mod:`safelane.sim`)
share it without the simulator's imports.
"""

from __future__ import annotations

import numpy as np


def stop_time(v, a, horizon):
    """Time at which a vehicle at speed ``v >= 0`` with acceleration ``a`` stops, capped at ``horizon``."""
    braking = a < 0.0
    safe = np.where(braking, -a, 1.0)
    with np.errstate(over="ignore"):  # a vanishing deceleration: v / tiny -> inf, then capped at the horizon
        return np.where(braking, np.minimum(v / safe, horizon), horizon)


def advance(x, v, a, dt):
    """Exact state after ``dt`` at constant acceleration ``a``, stopping at rest: ``(x', v')``."""
    ts = stop_time(v, a, dt)
    return x + v * ts + 0.5 * a * ts * ts, np.where(ts < dt, 0.0, np.maximum(v + a * dt, 0.0))


def free_max(y0, vy0, a, dt: float):
    """Exact maximum over ``[0, dt]`` of ``y0 + vy0 t + a t²/2`` (one constant-acceleration segment)."""
    end = y0 + vy0 * dt + 0.5 * a * dt * dt
    safe = np.where(a < 0.0, a, -1.0)
    tau = np.where(a < 0.0, -vy0 / safe, -1.0)
    vertex = np.where((tau > 0.0) & (tau < dt), y0 + 0.5 * vy0 * tau, -np.inf)
    return np.maximum(np.maximum(y0, end), vertex)
