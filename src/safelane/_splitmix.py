"""SplitMix64 (Steele et al. 2014) as closed forms on uint64 — NumPy arrays, or one value in compiled code: the
one source of the hash behind the counter-based draws (:mod:`safelane.sim.rng`) and the slow assessment's
per-scenario draws (:mod:`safelane.shield.policies`). Wrapping arithmetic is intended."""

from __future__ import annotations

import numpy as np

from .safety._backend import jitable

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def mix64(z):
    """SplitMix64's finaliser of ``z`` (uint64: an array, or one compiled value; products wrap)."""
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


def unit_of(h):
    """A uniform in ``[0, 1)`` from the top 53 bits of the uint64 ``h``."""
    return (h >> np.uint64(11)) * (1.0 / 2**53)


def absorb(h, c):
    """The hash ``h`` after one more counter ``c`` (both uint64): one step of
    :func:`safelane.sim.rng.counter_uniform`."""
    return mix64(h ^ (c * _GOLDEN + _GOLDEN))


def counter_uniform4(key, c1, c2, c3, c4):
    """:func:`safelane.sim.rng.counter_uniform` with four integer counters, for one compiled draw (``key``: the
    seed as a uint64)."""
    h = absorb(key, np.uint64(c1))
    h = absorb(h, np.uint64(c2))
    h = absorb(h, np.uint64(c3))
    return unit_of(absorb(h, np.uint64(c4)))


jitable(mix64, unit_of, absorb, counter_uniform4)
