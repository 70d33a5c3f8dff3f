"""Two interchangeable element-wise backends for the safety math.

The closed forms are written once against a tiny namespace ``xp`` (``where``, ``maximum``, ``minimum``,
``sqrt``, ``div``, ``stop_dist``). ``ARRAY`` maps it onto NumPy for batches; ``SCALAR`` maps it onto plain
Python floats, because a single check through NumPy pays ~1 µs of dispatch per operation and the scalar API
must answer in tens of microseconds. Both backends evaluate both branches of ``where``, so every division
goes through ``div`` (which never divides by zero) and every square root clamps its argument at zero.
"""

from __future__ import annotations

import math

import numpy as np

INF = math.inf

#: Gaps within this many metres of the margin count as satisfied (float round-off of the closed forms); the same
#: tolerance decides when a link's slack counts as exactly zero (``chain.min_follow_decel``).
FEASIBILITY_TOL_M = 1e-9


class _Scalar:
    """Python-float implementation (inputs are ``float``/``bool``)."""

    @staticmethod
    def where(cond, a, b):
        return a if cond else b

    @staticmethod
    def maximum(a, b):
        return a if a >= b else b

    @staticmethod
    def minimum(a, b):
        return a if a <= b else b

    @staticmethod
    def sqrt(x):
        return math.sqrt(x) if x > 0.0 else 0.0

    @staticmethod
    def clip(x, lo, hi):
        return lo if x < lo else (hi if x > hi else x)

    @staticmethod
    def div(num, den, default):
        return num / den if den != 0.0 else default

    @staticmethod
    def stop_dist(v, a):
        """Braking distance ``v²/(2a)``; infinite when ``a = 0`` and ``v > 0``."""
        if a > 0.0:
            return v * v / (2.0 * a)
        return INF if v > 0.0 else 0.0

    @staticmethod
    def stop_time(v, a):
        """Time to stop ``v/a``; infinite when ``a = 0`` and ``v > 0``."""
        if a > 0.0:
            return v / a
        return INF if v > 0.0 else 0.0


class _Array:
    """NumPy implementation (inputs are broadcastable float64/bool arrays)."""

    where = staticmethod(np.where)
    maximum = staticmethod(np.maximum)
    minimum = staticmethod(np.minimum)

    @staticmethod
    def sqrt(x):
        return np.sqrt(np.maximum(x, 0.0))

    @staticmethod
    def clip(x, lo, hi):
        return np.minimum(np.maximum(x, lo), hi)

    @staticmethod
    def div(num, den, default):
        safe = np.where(den != 0.0, den, 1.0)
        return np.where(den != 0.0, num / safe, default)

    @staticmethod
    def stop_dist(v, a):
        safe = np.where(a > 0.0, a, 1.0)
        return np.where(a > 0.0, v * v / (2.0 * safe), np.where(v > 0.0, INF, 0.0))

    @staticmethod
    def stop_time(v, a):
        safe = np.where(a > 0.0, a, 1.0)
        return np.where(a > 0.0, v / safe, np.where(v > 0.0, INF, 0.0))


SCALAR = _Scalar()
ARRAY = _Array()
