"""Nominal planners registered by name: ``get_nominal("mlp")`` → a :class:`~.base.NominalPlanner`.

One place lists every nominal planner a user (or an experiment, a benchmark, the CLI) can ask for by name, so
there is no if-chain over names anywhere else. Each entry is a factory: ``get_nominal`` builds a fresh planner
on every call (loading the shipped network reads its ``.npz``, so keep the instance when you call it often).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .base import ExpertPlanner, NominalPlanner
from .distilled import load_distilled_planner
from .nn import load_default_planner
from .teacher import OptimalControlTeacher


@dataclass(frozen=True)
class NominalEntry:
    """A registered nominal planner: its name, a factory and a one-line description."""

    name: str
    factory: Callable[[], NominalPlanner]
    description: str


NOMINAL_PLANNERS: dict[str, NominalEntry] = {
    e.name: e
    for e in (
        NominalEntry("expert", ExpertPlanner, "Rule-based PD planner (gap middle at L1's speed, smooth lateral)."),
        NominalEntry("mlp", load_default_planner, "The shipped neural planner (two MLPs; see models/MODEL_CARD.md)."),
        NominalEntry("teacher", OptimalControlTeacher, "Receding-horizon optimal-control teacher of the networks."),
        NominalEntry(
            "mlp_paper",
            load_distilled_planner,
            "The network distilled from the paper preset's calibrated rule-based planner (models/distill_paper.yaml).",
        ),
    )
}

#: Registry order.
NOMINAL_NAMES: tuple[str, ...] = tuple(NOMINAL_PLANNERS)


def get_nominal(name: str) -> NominalPlanner:
    """A new instance of the nominal planner registered as ``name``; ``ValueError`` listing the names otherwise."""
    try:
        entry = NOMINAL_PLANNERS[name]
    except KeyError:
        raise ValueError(f"unknown nominal planner {name!r}; choose one of {', '.join(NOMINAL_NAMES)}") from None
    return entry.factory()
