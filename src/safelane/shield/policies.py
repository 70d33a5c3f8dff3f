"""The shield's policy pieces, registered by name: each variant's information use, the aggressiveness
assessment, the completion rule.

* **Variants** (the paper's four, :data:`safelane.planners.variants.VARIANTS`): where L1's worst case and F's
  assumed type come from — the connected chain or ``a_x_d``; F's declared intent, the assessment, or "aggressive".
* **Assessments** (:data:`ASSESSMENTS`): ``observed`` — the slope-and-latch estimate from the ego's measurements of
  F's speed (:mod:`.assessment`); ``truth`` — F's true type from the situation (a study of the paper's guarantee,
  which assumes an exact assessment; no real ego has it).
* **Completion rules** (:data:`COMPLETION_RULES`): ``commit_guard`` — a step that takes the ego's centre across
  the lane boundary needs the ego able to keep ``p_m`` behind L1's worst case and a worst-case F able to keep
  ``p_m`` behind the ego, each braking at no more than ``a_x_d`` (:func:`.decide.commit_guard`).

A new assessment or completion rule is registered by adding it to the dictionary under a new name
(``ShieldConfig(assessment="mine")``).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..planners.variants import VARIANT_NAMES, VARIANTS, get_variant
from . import assessment as assess
from .decide import commit_guard


class Assessment(Protocol):
    """An aggressiveness assessment: ``start(n, config) -> state``; ``update(state, situation, dt, config) ->
    state`` once per period; ``aggressive(state, situation) -> (B,) bool``. The state must have a
    ``first_collaborative_s`` array (the results table reports it)."""

    def start(self, n: int, config): ...

    def update(self, state, situation, dt: float, config): ...

    def aggressive(self, state, situation) -> np.ndarray: ...


class ObservedAssessment:
    """``observed``: the least-squares slope of F's observed speed over a window, latched on aggressive evidence
    (:mod:`.assessment`)."""

    def start(self, n: int, config):
        return assess.AssessmentState.start(n, config.assess_window)

    def update(self, state, situation, dt: float, config):
        return assess.update(state, situation.observed_f_speed, situation.t, dt, config.assess_threshold)

    def aggressive(self, state, situation) -> np.ndarray:
        return state.aggressive


class TruthAssessment(ObservedAssessment):
    """``truth``: F's true type from ``Situation.f_aggressive_truth`` — simulation studies of the paper's guarantee,
    which assumes an exact assessment; no real ego has it. (The observed belief is still kept for the results.)"""

    def aggressive(self, state, situation) -> np.ndarray:
        if situation.f_aggressive_truth is None:
            raise ValueError("the 'truth' assessment needs Situation.f_aggressive_truth (a simulation study only)")
        return situation.f_aggressive_truth


ASSESSMENTS: dict[str, Assessment] = {"observed": ObservedAssessment(), "truth": TruthAssessment()}

#: Completion rules: ``rule(ex, evx, lx, lv, l1_decel, fx, fv, params) -> (n,) bool`` on the predicted states of the
#: rows whose step crosses the lane boundary (see :func:`.decide.commit_guard`).
COMPLETION_RULES = {"commit_guard": commit_guard}

_FLAGS = np.array([[v.uses_chain, v.uses_follower_v2x, v.uses_assessment] for v in VARIANTS.values()])


def variant_flags(variant, n: int):
    """``(uses_chain, uses_follower_v2x, uses_assessment)``, each ``(n,)`` bool, for a variant name or ``(n,)``
    names or registry indices."""
    if isinstance(variant, str):
        get_variant(variant)
        idx = np.full(n, VARIANT_NAMES.index(variant))
    else:
        arr = np.asarray(variant)
        if arr.dtype.kind in "US":
            for name in set(arr.tolist()):
                get_variant(name)
            idx = np.array([VARIANT_NAMES.index(v) for v in arr.tolist()])
        elif arr.dtype.kind in "iu":
            if arr.size and (arr.min() < 0 or arr.max() >= len(VARIANT_NAMES)):
                raise ValueError(f"variant indices must lie in [0, {len(VARIANT_NAMES) - 1}]; got {arr.tolist()}")
            idx = arr
        else:
            raise TypeError(f"variant must be a name or an array of names or indices; got {type(variant).__name__}")
        if idx.shape != (n,):
            raise ValueError(f"variant must have one entry per row ({n}); got shape {idx.shape}")
    flags = _FLAGS[idx]
    return flags[:, 0], flags[:, 1], flags[:, 2]


def check_policy(kind: str, name: str, registry: dict) -> str:
    if name not in registry:
        raise ValueError(f"unknown {kind} {name!r}; choose one of {', '.join(registry)}")
    return name
