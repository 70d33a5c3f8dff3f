"""Counter-based random numbers: a scenario's draws depend only on (seed, scenario id, step, slot).

Per-step randomness (promise violations, sensor noise) must not depend on which batch a scenario runs in,
so one scenario run alone reproduces its row of a big batch exactly. Each draw hashes its counters with
SplitMix64 (Steele et al. 2014), vectorized over NumPy ``uint64`` arrays (wrapping arithmetic is intended).
"""

from __future__ import annotations

import numpy as np

from .._splitmix import absorb, unit_of


def counter_uniform(key: int, *counters) -> np.ndarray:
    """Uniform draws in ``[0, 1)`` keyed by ``key`` and broadcast integer ``counters``."""
    with np.errstate(over="ignore"):
        h = np.asarray(np.uint64(key % 2**64))
        for c in counters:
            h = absorb(h, np.asarray(c).astype(np.uint64))
        return unit_of(h)


def counter_normal(key: int, *counters) -> np.ndarray:
    """Standard normal draws (Box–Muller on two counter-based uniforms)."""
    u1 = counter_uniform(key, *counters, 1)
    u2 = counter_uniform(key, *counters, 2)
    return np.sqrt(-2.0 * np.log1p(-u1)) * np.cos(2.0 * np.pi * u2)

