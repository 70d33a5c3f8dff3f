"""Worst-case safety analysis of a lane change (paper §3.3, Eqs. 1–9), exact and vectorized.

Every function takes scalars or arrays of any broadcastable batch shape (float64) and a
:class:`safelane.Params`; bad input raises ``ValueError`` naming the argument. See ``docs/safety.md``.
"""

from .chain import ChainResult, leader_chain, leader_position, worst_case_leader_decel
from .evasion import evasion_exists, follower_position, plan_evasion
from .lateral import lateral_evasion_time
from .longitudinal import FEASIBILITY_TOL_M, LongitudinalEvasion, longitudinal_evasion
from .plan import EvasionPlan, Reason

__all__ = [
    "FEASIBILITY_TOL_M",
    "ChainResult",
    "EvasionPlan",
    "LongitudinalEvasion",
    "Reason",
    "evasion_exists",
    "follower_position",
    "lateral_evasion_time",
    "leader_chain",
    "leader_position",
    "longitudinal_evasion",
    "plan_evasion",
    "worst_case_leader_decel",
]
