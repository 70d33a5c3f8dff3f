"""Nominal planners (rule-based expert, neural networks) and the planner-variant registry."""

from .base import STATE_FEATURES, ExpertPlanner, NominalPlanner, Observation

__all__ = ["STATE_FEATURES", "ExpertPlanner", "NominalPlanner", "Observation"]
