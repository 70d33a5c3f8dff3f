"""The experiment registry: every experiment of the paper (and beyond) as a typed config with paper defaults.

An experiment is a set of :class:`~safelane.experiments.grid.Cell` s (a grid) or, for ``fig5_example``, one
scenario traced under every planner. ``quick`` configs run the same code on a reduced grid in seconds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from .grid import Cell
from .modes import ModesConfig, modes_cells, run_modes
from .paper_data import DECELS, PLANNERS
from .rss_baseline import RssBaselineConfig, rss_cells, run_rss_baseline
from .rules_table import run_rules_table


class ExperimentConfig(BaseModel):
    """Settings shared by every grid experiment."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    samples: int = Field(1000, ge=1, description="Scenarios per cell (paper: resolution 0.001).")
    planners: tuple[str, ...] = PLANNERS
    decels: tuple[float, ...] = DECELS


class Fig4Config(ExperimentConfig):
    n_leaders: int = Field(5, ge=0)


class Table1Config(ExperimentConfig):
    n_leaders: tuple[int, ...] = (1, 3, 10)


class Fig5Config(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    n_leaders: int = 5
    decel: float = 5.0
    selection: Literal["illustrative", "fixed"] = Field(
        "illustrative",
        description="'illustrative': the first of `search` seeded scenarios of the cell in which CV_all completes "
        "and every other planner turns back (the paper's example; failing that, one where another planner turns "
        "back); 'fixed': ego_speed and gap below.",
    )
    search: int = Field(200, ge=1, description="Scenarios searched for an illustrative example.")
    ego_speed: float = Field(30.0, description="Initial ego speed of the fixed example [m/s].")
    gap: float = Field(19.5, description="Initial inter-vehicle distance δp of the fixed example [m].")
    planners: tuple[str, ...] = PLANNERS


class Fig6Config(ExperimentConfig):
    n_leaders: int = 10
    p_v: tuple[float, ...] = (0.0, 0.05, 0.1, 0.2, 0.3, 0.5)
    planners: tuple[str, ...] = ("CV_all",)


class PenetrationConfig(ExperimentConfig):
    penetration: tuple[float, ...] = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
    decels: tuple[float, ...] = (4.0,)


class LeadersConfig(ExperimentConfig):
    n_leaders: tuple[int, ...] = tuple(range(11))
    decels: tuple[float, ...] = (4.0,)


@dataclass(frozen=True)
class Experiment:
    """A registered experiment: its config type, how to build its cells, and a reduced ``quick`` config."""

    name: str
    description: str
    config_type: type[BaseModel]
    cells: Callable[[BaseModel], list[Cell]] | None  # None: a traced single-scenario experiment
    quick: dict
    beyond_paper: bool = False
    #: A runner of its own, ``run(config, *, preset, seed, workers, nominal, cache) -> (table, summary)``, for a grid
    #: that is more than cells (``rss_baseline``: the cells under several follower behaviours).
    run: Callable | None = None
    #: Its cells count in the paper's claims (``claims.check_claims``); False for a baseline under other conditions.
    feeds_claims: bool = True

    def default_config(self, quick: bool = False) -> BaseModel:
        return self.config_type(**(self.quick if quick else {}))


def _fig4(c: Fig4Config) -> list[Cell]:
    return [Cell(p, c.n_leaders, d) for d in c.decels for p in c.planners]


def _n_grid(c: Table1Config | LeadersConfig) -> list[Cell]:
    """Every N × a_x_N+1_d × planner (Table 1, and ours along N)."""
    return [Cell(p, n, d) for n in c.n_leaders for d in c.decels for p in c.planners]


def _fig6(c: Fig6Config) -> list[Cell]:
    return [Cell(p, c.n_leaders, d, p_v=pv) for pv in c.p_v for d in c.decels for p in c.planners]


def _penetration(c: PenetrationConfig) -> list[Cell]:
    return [Cell(p, 10, d, penetration=q) for q in c.penetration for d in c.decels for p in c.planners]


_QUICK = {"samples": 40}
EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment(
            "fig4_n5", "Success rate vs a_x_N+1_d for N = 5, all planners (paper Fig. 4).", Fig4Config, _fig4, _QUICK
        ),
        Experiment(
            "table1",
            "Success rates for N in {1, 3, 10} x a_x_N+1_d x planners (paper Table 1).",
            Table1Config,
            _n_grid,
            _QUICK,
        ),
        Experiment(
            "fig5_example",
            "One scenario, N = 5, a_x_N+1_d = 5: lateral position and speed over time "
            "under every planner (paper Fig. 5).",
            Fig5Config,
            None,
            {},
        ),
        Experiment(
            "fig6_violation",
            "Collision and success rate vs promise-violation rate p_v, N = 10 (paper Fig. 6).",
            Fig6Config,
            _fig6,
            {"samples": 40, "p_v": (0.0, 0.2, 0.5)},
        ),
        Experiment(
            "penetration",
            "Success vs share of connected vehicles (random placement; beyond the paper).",
            PenetrationConfig,
            _penetration,
            {"samples": 40, "penetration": (0.0, 0.5, 1.0)},
            True,
        ),
        Experiment(
            "leaders",
            "Success vs number of connected leaders N = 0..10 (beyond the paper).",
            LeadersConfig,
            _n_grid,
            {"samples": 40, "n_leaders": (0, 1, 5, 10)},
            True,
        ),
        Experiment(
            "rss_baseline",
            "RSS (ad-rss's model) against the paper's shield, with and without V2X: Table 1's grid x follower "
            "behaviour (collaborative, aggressive, ignoring the ego) x the paper's and the RSS variants (beyond the "
            "paper; docs/rss.md).",
            RssBaselineConfig,
            rss_cells,
            {"samples": 40},
            True,
            run_rss_baseline,
            False,
        ),
        Experiment(
            "table1_safe_mode",
            "The published Table 1 cells in safe mode (commit guard, worst-case leaders, monitor on) beside the "
            "paper-faithful preset's (docs/reproduction.md; safelane.experiments.modes).",
            ModesConfig,
            modes_cells,
            {"samples": 40},
            True,
            run_modes,
            False,
        ),
        Experiment(
            "table1_rules",
            "Table 1 with the rule-based planner the network is distilled from (the preset's expert), beside the "
            "reported table1, which runs the network (docs/reproduction.md; safelane.experiments.rules_table).",
            Table1Config,
            _n_grid,
            {"samples": 40},
            False,
            run_rules_table,
            False,
        ),
    )
}


def get_experiment(name: str) -> Experiment:
    try:
        return EXPERIMENTS[name]
    except KeyError:
        raise ValueError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}") from None
