"""The two modes side by side (docs/reproduction.md): the paper-faithful mode (the reproduction's) and the safe mode.

* **paper-faithful** — the ``paper`` preset: the paper's completion rule (``paper_evasion``: the crossing step is
  decided by the Eq. 9 evasion check alone), connected leaders that react to the braking ahead as it happens
  (``leader_rule: reactive``), no assumption monitor, the calibrated ``slow`` assessment. Outside the zero-violation
  guarantee; its measured violation rates are in docs/reproduction.md.
* **safe** — the same calibrated vehicles, planner and assessment with the guarantee's rules
  (:data:`SAFE_MODE`): the commit guard at the crossing step, leaders that keep a safe distance against the worst
  case ahead, the monitor on. The ``safe`` preset (``src/safelane/presets/safe.yaml``) is this.

:func:`run_modes` runs the published Table 1 cells (N = 1, 10) in safe mode; the report puts them beside the
paper-faithful Table 1.
"""

from __future__ import annotations

import dataclasses

import pandas as pd
from pydantic import BaseModel, ConfigDict, Field

from ..sim.metrics import summarize
from .grid import Cell, run_cells
from .paper_data import DECELS, PLANNERS, PUBLISHED_N

#: The safe mode's rules (SimConfig fields), applied on top of any preset.
SAFE_MODE = {"completion": "commit_guard", "leader_rule": "worst_case", "monitor": True}


class ModesConfig(BaseModel):
    """The grid of ``table1_safe_mode``: the published Table 1 cells."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    samples: int = Field(300, ge=1, description="Scenarios per cell (300 keeps `make run` fast; the MAE moves < 0.01).")
    planners: tuple[str, ...] = PLANNERS
    decels: tuple[float, ...] = DECELS
    n_leaders: tuple[int, ...] = PUBLISHED_N


def safe_preset(preset):
    """``preset`` with the safe mode's rules (:data:`SAFE_MODE`)."""
    return dataclasses.replace(preset, name=f"{preset.name} (safe mode)", sim=preset.sim.model_copy(update=SAFE_MODE))


def modes_cells(cfg: ModesConfig) -> list[Cell]:
    """The published Table 1 cells (run in safe mode by :func:`run_modes`)."""
    return [Cell(p, n, d) for n in cfg.n_leaders for d in cfg.decels for p in cfg.planners]


def run_modes(cfg: ModesConfig, *, preset, seed: int, workers, nominal, cache=None):
    """``(table, summary)`` of the grid in safe mode (``cache`` is not used: other settings, other outcomes)."""
    safe = safe_preset(preset)
    table = run_cells(
        modes_cells(cfg), cfg.samples, seed, params=safe.params, config=safe.sim, nominal=nominal, workers=workers
    )
    summary = summarize(table, by=("planner", "n_leaders", "decel", "p_v", "penetration"))
    return table, summary


def modes_side_by_side(paper_table1: pd.DataFrame, safe: pd.DataFrame) -> pd.DataFrame:
    """Per published cell: paper-faithful and safe-mode success with the paper's value."""
    from .paper_data import table1_long

    keys = ["planner", "n_leaders", "decel"]
    a = paper_table1[[*keys, "success_rate"]].rename(columns={"success_rate": "paper_faithful"})
    b = safe[[*keys, "success_rate", "collision_rate", "safety_violation_rate"]].rename(
        columns={"success_rate": "safe_mode", "collision_rate": "safe_collision", "safety_violation_rate":
                 "safe_violation"})  # fmt: skip
    return pd.DataFrame(table1_long()).merge(a, on=keys).merge(b, on=keys)
