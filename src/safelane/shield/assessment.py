"""Aggressiveness assessment of the follower from the ego's own observations.

ASP-DAC'23's method is not available to us, so this is our design. The ego observes F's speed every period
(optionally with Gaussian sensor noise) and estimates F's acceleration as the least-squares slope of ``v_F``
over the last ``window`` observations. The belief starts at "aggressive" (conservative) and switches only on
evidence:

* **aggressive evidence** — the slope is at least ``+threshold``: F speeds up, i.e. pushes to close the gap.
  It is *latched*: a follower that has once tried to close the gap stays "aggressive" for the rest of the
  manoeuvre (the conservative side; noise can only cost efficiency here, never safety).
* **collaborative evidence** — the slope is at most ``−threshold`` (F yields) and no aggressive evidence was
  ever seen.

The evidence is F's own (absolute) acceleration, not its acceleration relative to L1: a collaborative F that
opens the gap while L1 brakes harder looks like it *closes* on L1, and an aggressive F that closes on L1
fast must brake relative to it before it arrives (a responsible follower) and looks like it opens a gap —
relative evidence got both wrong. What the latch cannot tell apart is an aggressive F that is forced to brake
before it ever got to accelerate; in our scenario distributions an aggressive F always starts ``2 δp >= 34 m``
behind L1 at L1's speed, so it accelerates in its first periods.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..safety._backend import ARRAY, jitable


@dataclass(frozen=True)
class AssessmentState:
    history: np.ndarray  # (B, window) observed follower speeds v_F, oldest first
    count: np.ndarray  # (B,) observations so far
    aggressive: np.ndarray  # (B,) current belief
    latched: np.ndarray  # (B,) aggressive evidence seen: the belief stays "aggressive"
    first_collaborative_s: np.ndarray  # (B,) time of the first "collaborative" verdict (nan if never)

    @classmethod
    def start(cls, batch: int, window: int) -> AssessmentState:
        return cls(
            history=np.zeros((batch, window)),
            count=np.zeros(batch, dtype=np.int64),
            aggressive=np.ones(batch, dtype=bool),
            latched=np.zeros(batch, dtype=bool),
            first_collaborative_s=np.full(batch, np.nan),
        )


def update(state: AssessmentState, f_speed, t: float, dt: float, threshold: float) -> AssessmentState:
    """Add one observation of F's speed ``v_F`` taken at time ``t`` and revise the belief."""
    window = state.history.shape[1]
    history = np.concatenate([state.history[:, 1:], f_speed[:, None]], axis=1)
    count = state.count + 1
    times = (np.arange(window) - (window - 1) / 2.0) * dt
    slope = _dot(history, times) / _dot(times[None, :], times)[0]
    latched, aggressive = belief_core(ARRAY, slope, count >= window, state.latched, state.aggressive, threshold)
    first = np.where(np.isnan(state.first_collaborative_s) & ~aggressive, t, state.first_collaborative_s)
    return AssessmentState(history, count, aggressive, latched, first)


def belief_core(xp, slope, full, latched, aggressive, threshold):
    """``(latched, aggressive)`` after one slope of F's speed, backend-generic (the one source of the rule; the
    compiled closed loop evaluates it per row): the window ``full``, a slope of at least ``+threshold`` latches
    "aggressive"; at most ``−threshold`` gives "collaborative" unless latched; else the belief stays."""
    latched = latched | (full & (slope >= threshold))
    return latched, latched | xp.where(full & (slope <= -threshold), False, aggressive)


def _dot(rows, weights):
    """``rows @ weights`` summed left to right in a fixed order: a BLAS product's rounding depends on the build, the
    CPU and the array's layout, which would make the belief (a threshold on the slope) machine-dependent."""
    out = rows[:, 0] * weights[0]
    for j in range(1, len(weights)):
        out = out + rows[:, j] * weights[j]
    return out


jitable(belief_core)
