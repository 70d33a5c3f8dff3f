"""Exact one-segment motion at constant acceleration, stopping at rest (speed never goes negative).

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
