"""Batched closed-loop simulation of the lane change (scenarios, behaviours, supervisor, metrics)."""

from .engine import SimConfig, SimResult, simulate, simulate_batch
from .metrics import summarize, wilson_interval
from .scenario import ScenarioBatch, ScenarioConfig, concat, paper_scenarios, penetration_scenarios
from .step import SimState

__all__ = [
    "ScenarioBatch",
    "ScenarioConfig",
    "SimConfig",
    "SimResult",
    "SimState",
    "concat",
    "paper_scenarios",
    "penetration_scenarios",
    "simulate",
    "simulate_batch",
    "summarize",
    "wilson_interval",
]
