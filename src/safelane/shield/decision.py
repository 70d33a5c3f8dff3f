"""The shield's answer for one period (:class:`Decision`)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..safety.plan import EvasionPlan
from .decide import ABORT, COMPLETED, HESITATE, PROCEED
from .monitor import Breach


@dataclass(frozen=True)
class Decision:
    """The shield's answer for one period (``(B,)`` arrays unless noted).

    Attributes:
        behaviour: :data:`PROCEED`, :data:`HESITATE`, :data:`ABORT` or :data:`COMPLETED` (the lane change is done;
            the ego follows L1 responsibly).
        a_x, a_y: the accelerations to apply for the period [m/s²] (shield frame). For an aborting row they are the
            held plan's at the period's start; the plan switches inside the period, so apply :meth:`abort_motion`
            where the simulator can (exact), or re-ask the shield every period.
        completing: this period's motion takes the ego's centre across the lane boundary.
        invalid: the proposal was invalid (non-finite or out of range) and never executed.
        plan, plan_t0: the held plan after this decision (verified from the predicted state at the period's end).
        l1_decel: L1's worst-case deceleration used; f_aggressive: F's assumed type.
        breach: the assumption monitor's record (which assumption broke, and when).
        nominal_x, nominal_y: the proposal as given (after the type and shape checks).
    """

    behaviour: np.ndarray
    a_x: np.ndarray
    a_y: np.ndarray
    completing: np.ndarray
    invalid: np.ndarray
    _plan: EvasionPlan | Callable[[], EvasionPlan]  # the plan, or what builds it when first read (the compiled path)
    plan_t0: np.ndarray
    l1_decel: np.ndarray
    f_aggressive: np.ndarray
    breach: Breach
    nominal_x: np.ndarray
    nominal_y: np.ndarray
    _abort: tuple  # (rows, knots, px, vx, py, vy) of the aborting rows' exact motion over the period

    @functools.cached_property
    def plan(self) -> EvasionPlan:
        """The held plan after this decision (built from the compiled period's arrays when first read)."""
        return self._plan() if callable(self._plan) else self._plan

    @property
    def intervened(self) -> np.ndarray:
        """The executed command differs from the proposal (hesitate, abort, or an invalid proposal)."""
        return (self.behaviour == HESITATE) | (self.behaviour == ABORT) | self.invalid

    def abort_motion(self):
        """``(rows, knots, px, vx, py, vy)``: the exact motion of the aborting rows over the period (knots relative
        to its start, shield frame)."""
        return self._abort

    def reasons(self) -> list[str]:
        """A readable reason per row."""
        names = {PROCEED: "proceed: the proposal keeps a safe evasion", COMPLETED: "completed: following L1"}
        out = []
        for i, code in enumerate(self.behaviour.tolist()):
            why = names.get(code)
            if code == HESITATE:
                why = "hesitate: " + ("invalid proposal" if self.invalid[i] else "the proposal leaves no safe evasion")
            elif code == ABORT:
                why = "abort: neither the proposal nor hesitating keeps a safe evasion; executing the held plan"
            if self.breach.flags[i].any():
                why += " (assumptions breached: most conservative worst case)"
            out.append(why)
        return out
