"""Nominal planners (rule-based expert, neural networks) and the planner-variant registry."""

from .base import STATE_FEATURES, ExpertPlanner, NominalPlanner, Observation

__all__ = ["STATE_FEATURES", "ExpertPlanner", "NominalPlanner", "Observation"]

from .variants import VARIANT_NAMES, VARIANTS, Variant, get_variant

__all__ += ["VARIANTS", "VARIANT_NAMES", "Variant", "get_variant"]
