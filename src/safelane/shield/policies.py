"""The shield's policy pieces, registered by name: each variant's information use, the aggressiveness
assessment, the completion rule.

* **Variants** (the paper's four, :data:`safelane.planners.variants.VARIANTS`): where L1's worst case and F's
  assumed type come from — the connected chain or ``a_x_d``; F's declared intent, the assessment, or "aggressive".
* **Assessments** (:data:`ASSESSMENTS`): ``observed`` — the slope-and-latch estimate from the ego's measurements of
  F's speed (:mod:`.assessment`); ``truth`` — F's true type from the situation (a study of the paper's guarantee,
  which assumes an exact assessment; no real ego has it).
* **Completion rules** (:data:`COMPLETION_RULES`): ``commit_guard`` — a step that takes the ego's centre across
  the lane boundary needs the ego able to keep ``p_m`` behind L1's worst case and a worst-case F able to keep
  ``p_m`` behind the ego, each braking at no more than ``a_x_d`` (:func:`.decide.commit_guard`); the safe mode's,
  the one the zero-violation guarantee covers. ``paper_evasion`` — the paper's rule: the crossing step is checked
  like every other step, by the Eq. 9 evasion check from the predicted state alone (:func:`paper_evasion`); the
  paper-faithful mode's, outside the guarantee (after the crossing the ego follows L1 responsibly, and L1's worst
  case may already be closer than the ego can absorb; measured rates in docs/reproduction.md).
* ``slow`` assessment (:class:`SlowAssessment`): the ``observed`` one, slowed and imperfect as a learned
  classifier of driving styles is (ASP-DAC'23-style: it needs a stretch of F's trajectory): each ``collaborative``
  verdict is released only after a per-scenario random extra delay (uniform on ``[0.5, 1.5] · assess_delay_s``),
  and with probability ``assess_miss`` a collaborative F is never recognised. Both errors are on the conservative
  side (F taken for aggressive), so the guarantee is unaffected.

A new assessment or completion rule is registered by adding it to the dictionary under a new name
(``ShieldConfig(assessment="mine")``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .._splitmix import mix64, unit_of
from ..planners.variants import VARIANT_NAMES, VARIANTS, get_variant
from ..safety._backend import ARRAY, jitable
from ..tolerances import TIME_TOL_S
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


def _scenario_uniform(x0, v0, salt: int) -> np.ndarray:
    """A uniform draw in ``[0, 1)`` per row, keyed by the bits of F's first observed state (so a scenario's draw does
    not depend on the batch it is simulated in, and needs no id): :func:`uniform_of_bits` of their bits."""
    bits = lambda a: np.asarray(a, np.float64).view(np.uint64)  # noqa: E731
    with np.errstate(over="ignore"):
        return uniform_of_bits(bits(x0), bits(v0), salt)


def uniform_of_bits(hx, hv, salt):
    """A uniform in ``[0, 1)`` from two 64-bit keys (uint64 arrays, or one compiled uint64 each) and a ``salt``:
    SplitMix64's finaliser (``sim/rng.mix64``; unsigned products wrap, as intended)."""
    return unit_of(mix64((hx * np.uint64(0x9E3779B97F4A7C15)) ^ (hv + np.uint64(salt))))


def slow_draws(xp, key_x, key_v, delay_s, miss, hx, hv):
    """The slow assessment's per-scenario draws at F's first observation: the extra delay of a collaborative verdict
    (uniform on ``[0.5, 1.5] · delay_s``) and whether a collaborative F is never recognised (probability ``miss``);
    ``hx``, ``hv``: the bits of ``key_x``, ``key_v``."""
    return delay_s * (0.5 + uniform_of_bits(hx, hv, 1)), uniform_of_bits(hx, hv, 2) < miss


def slow_belief(xp, t, first_collaborative_s, delay_s, time_tol, aggressive, missed):
    """The slow assessment's released belief: aggressive unless the observed one says collaborative, the scenario's
    F is not missed and its verdict is ``delay_s`` old."""
    released = (t - first_collaborative_s) >= delay_s - time_tol
    return xp.where(released, aggressive | missed, True)


@dataclass(frozen=True)
class SlowState:
    """The observed assessment's state plus the slow one's per-scenario delay and miss draws."""

    inner: assess.AssessmentState
    delay_s: np.ndarray  # (B,) extra delay of a collaborative verdict [s]
    missed: np.ndarray  # (B,) this scenario's collaborative F is never recognised
    aggressive: np.ndarray  # (B,) the released belief

    @property
    def first_collaborative_s(self) -> np.ndarray:
        return np.where(self.aggressive, np.nan, self.inner.first_collaborative_s + self.delay_s)


class SlowAssessment(ObservedAssessment):
    """``slow``: the observed estimate with a random extra delay and a miss rate (module docstring). Plausible
    ranges (documented in docs/reproduction.md): delay 0.5–3 s (a classifier over 1–3 s of trajectory), miss
    0–0.3."""

    def start(self, n: int, config):
        return SlowState(super().start(n, config), np.zeros(n), np.zeros(n, bool), np.ones(n, bool))

    def update(self, state, situation, dt: float, config):
        inner = super().update(state.inner, situation, dt, config)
        delay, missed = state.delay_s, state.missed
        fresh = inner.count == 1  # a row's first observation: draw its delay and miss
        if fresh.any():
            key_x, key_v = situation.f_x - situation.ego_x, situation.observed_f_speed
            bits = lambda a: np.asarray(a, np.float64).view(np.uint64)  # noqa: E731
            with np.errstate(over="ignore"):
                d, m = slow_draws(ARRAY, key_x, key_v, config.assess_delay_s, config.assess_miss, bits(key_x),
                                  bits(key_v))  # fmt: skip
            delay, missed = np.where(fresh, d, delay), np.where(fresh, m, missed)
        aggressive = slow_belief(ARRAY, situation.t, inner.first_collaborative_s, delay, TIME_TOL_S, inner.aggressive,
                                 missed)  # fmt: skip
        return SlowState(inner, delay, missed, aggressive)

    def aggressive(self, state, situation) -> np.ndarray:
        return state.aggressive


ASSESSMENTS: dict[str, Assessment] = {
    "observed": ObservedAssessment(),
    "truth": TruthAssessment(),
    "slow": SlowAssessment(),
}


def paper_evasion(ex, evx, lx, lv, l1_decel, fx, fv, prm):
    """The completion rule ``paper_evasion`` (the paper's): no extra test at the crossing step — the evasion check
    of Eq. 9 from the predicted state decides it as it decides every step (``needs_evasion``). The paper counts a
    lane change as successful if the ego "finally crosses the border ... within the simulation horizon without any
    collision"; here a crossing is final (after it the ego follows L1), so "finally" is the first accepted crossing
    and success is "completed and no collision" over the horizon."""
    return np.ones(np.shape(ex), bool)


paper_evasion.needs_evasion = True


def paper_body_across(ex, evx, lx, lv, l1_decel, fx, fv, prm):
    """The completion rule ``paper_body_across``: the paper's rule (:func:`paper_evasion`: the evasion check alone
    decides every step), with "crosses the border" read as the *whole car* across it — the lane change completes
    when the ego's centre is half a vehicle width past the boundary (:attr:`level`). Until then the ego is still
    checked every period and may turn back, as the paper's evasion (a return to the original lane) allows."""
    return np.ones(np.shape(ex), bool)


paper_body_across.needs_evasion = True
paper_body_across.level = lambda prm: prm.y_boundary + 0.5 * prm.vehicle_width

#: Completion rules: ``rule(ex, evx, lx, lv, l1_decel, fx, fv, params) -> (n,) bool`` on the predicted states of the
#: rows whose step crosses the lane boundary (see :func:`.decide.commit_guard`); a rule with the attribute
#: ``needs_evasion = True`` also requires the step's evasion check (:func:`paper_evasion`); one with ``level(params)``
#: completes at that lateral position instead of the lane boundary (:func:`paper_body_across`).
COMPLETION_RULES = {
    "commit_guard": commit_guard,
    "paper_evasion": paper_evasion,
    "paper_body_across": paper_body_across,
}

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


jitable(uniform_of_bits, slow_draws, slow_belief)
