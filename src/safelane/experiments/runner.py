"""Run registered experiments under a preset and summarise them per cell."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pandas as pd
from pydantic import BaseModel

from ..parallel import Backend
from ..planners.base import NominalPlanner
from ..sim.engine import simulate_batch
from ..sim.metrics import summarize
from ..sim.scenario import ScenarioBatch, ScenarioConfig, concat, paper_scenarios
from .calibration import Preset, load_preset
from .grid import Cell, cell_batch, run_cells
from .registry import Fig5Config, get_experiment

SUMMARY_KEYS = ("planner", "n_leaders", "decel", "p_v", "penetration")


@dataclass
class ExperimentResult:
    """What one experiment produced: per-scenario table, per-cell summary, optional trace, wall time."""

    name: str
    config: BaseModel
    table: pd.DataFrame | None
    summary: pd.DataFrame | None
    trace: pd.DataFrame | None
    elapsed_s: float


def run_experiment(
    name: str,
    config: BaseModel | None = None,
    *,
    preset: Preset | None = None,
    seed: int = 0,
    quick: bool = False,
    workers: int | Backend = 1,
    nominal: NominalPlanner | None = None,
    cache: dict | None = None,
) -> ExperimentResult:
    """Run the registered experiment ``name`` (its default or ``quick`` config unless ``config`` is given).

    ``cache``: cells already simulated under the same preset, seed and nominal planner (see :func:`run_cells`);
    ``reproduce`` shares one across its experiments, so a cell two experiments list runs once."""
    exp = get_experiment(name)
    cfg = config or exp.default_config(quick)
    preset = preset or load_preset("paper")
    nominal = nominal or preset.nominal()
    start = time.perf_counter()
    if exp.run is not None:
        table, summary = exp.run(cfg, preset=preset, seed=seed, workers=workers, nominal=nominal, cache=cache)
        return ExperimentResult(name, cfg, table, summary, None, time.perf_counter() - start)
    if exp.cells is None:
        trace = _trace_example(cfg, preset, seed, nominal)
        return ExperimentResult(name, cfg, None, None, trace, time.perf_counter() - start)
    cells = exp.cells(cfg)
    table = run_cells(
        cells, cfg.samples, seed, params=preset.params, config=preset.sim, nominal=nominal, workers=workers, cache=cache
    )
    keys = SUMMARY_KEYS
    if any(c.penetration is not None for c in cells):
        # The general sampler draws N per scenario: a cell is (planner, decel, p_v, penetration), not split by N.
        keys = tuple(k for k in SUMMARY_KEYS if k != "n_leaders")
    summary = summarize(table, by=keys)
    return ExperimentResult(name, cfg, table, summary, None, time.perf_counter() - start)


def _trace_example(cfg: Fig5Config, preset: Preset, seed: int, nominal) -> pd.DataFrame:
    """One scenario traced under every planner: an illustrative one found in the seeded cell, or a fixed one."""
    batch = _illustrative_example(cfg, preset, seed, nominal) if cfg.selection == "illustrative" else None
    if batch is None:
        batch = _fixed_example(cfg, seed)
    result = simulate_batch(
        batch, seed=seed, params=preset.params, config=preset.sim, nominal=nominal, trace=True, trace_limit=len(batch)
    )
    return result.trace


def _illustrative_example(cfg: Fig5Config, preset: Preset, seed: int, nominal) -> ScenarioBatch | None:
    """The first scenario of the cell where CV_all completes and some other planner does not complete or aborts."""
    cells = [Cell(p, cfg.n_leaders, cfg.decel) for p in cfg.planners]
    table = run_cells(cells, cfg.search, seed, params=preset.params, config=preset.sim, nominal=nominal)
    success = table.pivot(index="scenario_id", columns="planner", values="success")
    aborts = table.pivot(index="scenario_id", columns="planner", values="n_abort")
    others = [p for p in cfg.planners if p != "CV_all"]
    if "CV_all" not in success or not others:
        return None
    # The paper's own example: CV_all completes and every other planner turns back; else any other one does.
    wanted = success["CV_all"] & (~success[others]).all(axis=1)
    if not wanted.any():
        wanted = success["CV_all"] & ((~success[others]).any(axis=1) | (aborts[others] > 0).any(axis=1))
    if not wanted.any():
        return None
    row = int(np.flatnonzero(wanted.to_numpy())[0])
    return concat([cell_batch(c, cfg.search, seed, None).take([row]) for c in cells])


def _fixed_example(cfg: Fig5Config, seed: int) -> ScenarioBatch:
    parts = []
    for planner in cfg.planners:
        b = paper_scenarios(planner, cfg.n_leaders, cfg.decel, 1, np.random.default_rng(seed), ScenarioConfig())
        x = b.x / np.abs(b.x[:, :1]) * cfg.gap  # F at -δp, L_i at i·δp with the example's δp
        parts.append(ScenarioBatch(**{**b.__dict__, "x": x, "ego_vx": np.array([cfg.ego_speed])}))
    return concat(parts)
