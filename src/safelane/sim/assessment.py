"""Aggressiveness assessment of the follower from the ego's own observations.

ASP-DAC'23's method is not available to us, so this is our design. The ego observes F's and L1's speeds every
period (optionally with Gaussian sensor noise) and estimates F's acceleration *relative to L1's* as the
least-squares slope of ``v_F − v_L1`` over the last ``window`` observations. Relative acceleration is the
evidence because an aggressive follower that has closed up on a braking L1 brakes too, and must not be
mistaken for one opening a gap. The belief starts at "aggressive" (conservative) and switches only on
evidence: to collaborative when the slope is at most ``−threshold`` (F opens the gap), back to aggressive when
it is at least ``+threshold``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AssessmentState:
    history: np.ndarray  # (B, window) relative speeds v_F − v_L1, oldest first
    count: np.ndarray  # (B,) observations so far
    aggressive: np.ndarray  # (B,) current belief
    first_collaborative_s: np.ndarray  # (B,) time of the first "collaborative" verdict (nan if never)

    @classmethod
    def start(cls, batch: int, window: int) -> AssessmentState:
        return cls(
            history=np.zeros((batch, window)),
            count=np.zeros(batch, dtype=np.int64),
            aggressive=np.ones(batch, dtype=bool),
            first_collaborative_s=np.full(batch, np.nan),
        )


def update(state: AssessmentState, rel_speed, t: float, dt: float, threshold: float) -> AssessmentState:
    """Add one observation of ``v_F − v_L1`` taken at time ``t`` and revise the belief."""
    window = state.history.shape[1]
    history = np.concatenate([state.history[:, 1:], rel_speed[:, None]], axis=1)
    count = state.count + 1
    times = (np.arange(window) - (window - 1) / 2.0) * dt
    slope = history @ times / (times @ times)
    full = count >= window
    aggressive = np.where(full & (slope <= -threshold), False, state.aggressive)
    aggressive = np.where(full & (slope >= threshold), True, aggressive)
    first = np.where(np.isnan(state.first_collaborative_s) & ~aggressive, t, state.first_collaborative_s)
    return AssessmentState(history, count, aggressive, first)
