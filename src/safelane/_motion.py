"""Exact one-segment motion at constant acceleration, stopping at rest (speed never goes negative).

:func:`stop_time_core` and :func:`advance_core` are the rule, written once against a backend ``xp`` (``where``,
``minimum``, ``maximum``; :mod:`safelane.safety._backend`): on NumPy arrays here and in the safety math, on floats
compiled into the kernels (:mod:`safelane.safety.responsible` marks them ``jitable``; ``_fast_responsible._advance``
is a row of :func:`advance_core`). :func:`stop_time` and :func:`advance` pass ``numpy`` itself as the backend —
those three operations of ``_backend.ARRAY`` are NumPy's own — so this module imports nothing from
:mod:`safelane.safety`, and :mod:`safelane.v2x` (imported with the package) and the simulator share it without
their imports. (The maximum of a free, non-stopping segment — the conflict zone's test — is
:func:`safelane.shield.decide.lateral_max`.)
"""

from __future__ import annotations

import numpy as np


def stop_time_core(xp, v, a, horizon):
    """Backend-generic :func:`stop_time`. The divisor is ``-a`` only where ``a < 0`` (1 elsewhere, where the quotient
    is not used), so a float backend never divides by zero."""
    braking = a < 0.0
    return xp.where(braking, xp.minimum(v / xp.where(braking, -a, 1.0), horizon), horizon)


def advance_core(xp, x, v, a, dt):
    """Backend-generic :func:`advance`: ``(x', v')``."""
    ts = stop_time_core(xp, v, a, dt)
    return x + v * ts + 0.5 * a * ts * ts, xp.where(ts < dt, 0.0, xp.maximum(v + a * dt, 0.0))


def piece_acc(xp, v0, v1, span):
    """The constant acceleration of a segment of length ``span`` from its end speeds ``v0``, ``v1`` (0 on a
    zero-length segment: a repeated knot). Backend-generic: the simulator's motions (``sim/kinematics.py``) and the
    shield's commands (``shield/command.py``)."""
    return xp.where(span > 0.0, (v1 - v0) / xp.where(span > 0.0, span, 1.0), 0.0)


def stop_time(v, a, horizon):
    """Time at which a vehicle at speed ``v >= 0`` with acceleration ``a`` stops, capped at ``horizon``."""
    with np.errstate(over="ignore"):  # a vanishing deceleration: v / tiny -> inf, then capped at the horizon
        return stop_time_core(np, v, a, horizon)


def advance(x, v, a, dt):
    """Exact state after ``dt`` at constant acceleration ``a``, stopping at rest: ``(x', v')``."""
    with np.errstate(over="ignore"):  # as stop_time
        return advance_core(np, x, v, a, dt)
