"""Run a grid of experiment cells as one batch (a Monte-Carlo sweep is just a bigger batch)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..parallel import Backend
from ..params import Params
from ..planners.base import NominalPlanner
from ..sim.engine import SimConfig, simulate_batch
from ..sim.inputs import cell_rng as _cell_rng
from ..sim.scenario import ScenarioConfig, concat, paper_scenarios, penetration_scenarios


@dataclass(frozen=True)
class Cell:
    """One experiment cell: planner variant × N × a_x_N+1_d × p_v (× penetration for the general sampler)."""

    planner: str
    n_leaders: int = 5
    decel: float = 5.0
    p_v: float = 0.0
    penetration: float | None = None  # None: the paper's sampler (L1..LN connected, F connected)


def cell_rng(seed: int, cell: Cell) -> np.random.Generator:
    """The generator of a cell's initial states: keyed by the run seed and the cell's scenario settings only,
    so a cell gives the same numbers whichever grid it runs in, and every planner sees the same scenarios
    (common random numbers: planner differences are not sampling noise)."""
    return _cell_rng(seed, cell.n_leaders, cell.decel, cell.p_v, cell.penetration)  # the one scheme: sim/inputs


def run_cells(
    cells: Sequence[Cell],
    samples: int,
    seed: int = 0,
    *,
    params: Params | None = None,
    config: SimConfig | None = None,
    scenario: ScenarioConfig | None = None,
    nominal: NominalPlanner | None = None,
    progress: bool = False,
    workers: int | Backend = 1,
    max_batch: int = 16384,
    cache: dict[tuple[Cell, int], pd.DataFrame] | None = None,
) -> pd.DataFrame:
    """Simulate ``samples`` scenarios of every cell; returns the per-scenario table (with a ``cell`` column).

    Cells run together in batches of at most ``max_batch`` scenarios (memory stays bounded). Scenario ids
    restart at 0 in every cell, so per-step random draws are shared across cells as well (common random
    numbers); a cell's rows never depend on the other cells of the run. So a cell is simulated once however
    often it is listed, and ``cache`` (keyed by ``(cell, samples)``) carries its rows across calls that share
    ``seed``, ``params``, ``config``, ``scenario`` and ``nominal`` — the caller's promise. ``workers``: a number
    of local processes or a :class:`~safelane.parallel.Backend` (the table is the same on every one).
    """
    if not cells:
        raise ValueError("cells must not be empty")
    if samples < 1:
        raise ValueError(f"samples must be >= 1; got {samples}")
    cache = {} if cache is None else cache
    todo = [c for c in dict.fromkeys(cells) if (c, samples) not in cache]
    per_batch = max(1, max_batch // samples)
    for start in range(0, len(todo), per_batch):
        group = todo[start : start + per_batch]
        batch = concat([cell_batch(c, samples, seed, scenario) for c in group])
        result = simulate_batch(
            batch, seed=seed, params=params, config=config, nominal=nominal, progress=progress, workers=workers
        )
        for k, cell in enumerate(group):
            cache[cell, samples] = result.table.iloc[k * samples : (k + 1) * samples]
    table = pd.concat([cache[c, samples] for c in cells], ignore_index=True)
    table["cell"] = np.repeat(np.arange(len(cells)), samples)
    if any(c.penetration is not None for c in cells):
        table["penetration"] = np.repeat([np.nan if c.penetration is None else c.penetration for c in cells], samples)
    return table


def cell_batch(cell: Cell, samples: int, seed: int, scenario: ScenarioConfig | None):
    rng = cell_rng(seed, cell)
    if cell.penetration is None:
        return paper_scenarios(cell.planner, cell.n_leaders, cell.decel, samples, rng, scenario, p_v=cell.p_v)
    return penetration_scenarios(cell.planner, cell.penetration, cell.decel, samples, rng, scenario, p_v=cell.p_v)
