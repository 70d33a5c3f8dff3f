"""Batched closed-loop simulation of the lane change: scenarios, traffic, the shield in the loop, exact checks."""

from .engine import SimConfig, SimResult, simulate, simulate_batch
from .metrics import summarize, wilson_interval
from .scenario import ScenarioBatch, ScenarioConfig, concat, explicit_scenarios, paper_scenarios, penetration_scenarios
from .step import SimState
from .traffic import TRAFFIC_MODELS, PaperTraffic, TrafficHooks, TrafficModel, TrafficView, with_last_profile

__all__ = [
    "TRAFFIC_MODELS",
    "PaperTraffic",
    "ScenarioBatch",
    "ScenarioConfig",
    "SimConfig",
    "SimResult",
    "SimState",
    "TrafficHooks",
    "TrafficModel",
    "TrafficView",
    "concat",
    "explicit_scenarios",
    "paper_scenarios",
    "penetration_scenarios",
    "simulate",
    "simulate_batch",
    "summarize",
    "wilson_interval",
    "with_last_profile",
]
