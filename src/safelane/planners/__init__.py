"""Nominal planners (rule-based expert, optimal-control teacher, neural networks), their registry by name, and
the planner-variant registry."""

from .base import STATE_FEATURES, ExpertPlanner, NominalPlanner, Observation
from .nn import MLPPlanner, load_default_planner
from .registry import NOMINAL_NAMES, NOMINAL_PLANNERS, NominalEntry, get_nominal
from .teacher import OptimalControlTeacher, TeacherConfig
from .variants import VARIANT_NAMES, VARIANTS, Variant, get_variant

__all__ = [
    "NOMINAL_NAMES",
    "NOMINAL_PLANNERS",
    "STATE_FEATURES",
    "VARIANTS",
    "VARIANT_NAMES",
    "ExpertPlanner",
    "MLPPlanner",
    "NominalEntry",
    "NominalPlanner",
    "Observation",
    "OptimalControlTeacher",
    "TeacherConfig",
    "Variant",
    "get_nominal",
    "get_variant",
    "load_default_planner",
]
