"""The shield: safelane's runtime supervisor as a standalone component any simulator can call.

``Shield(params, variant=..., config=...)``: ``reset(situation)``, then every period ``step(situation, proposal) ->
Decision`` — over a pure functional core (``init``, ``step``). A :class:`Situation` is what the ego knows (its state,
F's sensed state and V2X status, the leader chain); a :class:`Decision` says proceed / hesitate / abort /
completed, the accelerations to apply, the verified plan, the worst case used, and what the assumption monitor saw.
See docs/architecture.md.
"""

from .core import Shield, ShieldConfig, ShieldState, chain_analysis, init, step
from .decide import ABORT, COMPLETED, HESITATE, PROCEED
from .decision import Decision
from .geometry import GeometryWarning
from .monitor import BREACH_KINDS, Breach
from .policies import ASSESSMENTS, COMPLETION_RULES
from .situation import LaneFrame, SensingBounds, Situation

__all__ = [
    "ABORT",
    "ASSESSMENTS",
    "BREACH_KINDS",
    "COMPLETED",
    "COMPLETION_RULES",
    "HESITATE",
    "PROCEED",
    "Breach",
    "Decision",
    "GeometryWarning",
    "LaneFrame",
    "SensingBounds",
    "Shield",
    "ShieldConfig",
    "ShieldState",
    "Situation",
    "chain_analysis",
    "init",
    "step",
]
