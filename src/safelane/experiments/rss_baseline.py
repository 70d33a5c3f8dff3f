"""The experiment ``rss_baseline``: the industry's safety model (RSS, as ad-rss implements it) against this paper's
shield on the same lane changes, with and without V2X (docs/rss.md).

The Table 1 grid (N ∈ {1, 3, 10} × a_x_N+1_d ∈ {2..6}) × follower behaviour × planner variant (the paper's four and
the four RSS variants), every variant on the same sampled scenarios of a cell (common random numbers: the behaviours
change F's type and reaction only, never a draw):

* ``collaborative`` — the paper's F: connected, declares itself collaborative and yields (the sampler's default);
* ``aggressive`` — as the paper defines it: not connected, accelerates to close the gap and never yields;
* ``ignores_ego`` — connected and declaring itself collaborative, but never yielding to the ego
  (``SimConfig(follower_ignores_ego=True)``): outside the assumptions of both this paper and RSS.

Per scenario, besides the simulator's outcomes: whom the ego collided with (F or L1), which is what RSS's blame
rule needs (a rear-end by F after the ego entered at RSS's safe distance is F's fault by RSS; the table counts it as
a collision all the same).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field

from ..planners.variants import VARIANT_NAMES, get_variant
from ..sim.metrics import summarize, wilson_interval
from ..sim.scenario import ScenarioConfig
from .grid import Cell, run_cells
from .paper_data import DECELS

Follower = Literal["collaborative", "aggressive", "ignores_ego"]

#: Follower behaviour -> (ScenarioConfig overrides, SimConfig overrides). Same draws in every behaviour.
FOLLOWERS: dict[str, tuple[dict, dict]] = {
    "collaborative": ({}, {}),
    "aggressive": ({"follower_connected_share": 0.0, "follower_aggressive_share": 1.0}, {}),
    "ignores_ego": ({}, {"follower_ignores_ego": True}),
}


class RssBaselineConfig(BaseModel):
    """The grid of ``rss_baseline``."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    samples: int = Field(
        300, ge=1, description="Scenarios per cell (8 variants x 3 follower behaviours per grid cell: 108,000 lane "
        "changes in all, pooled per behaviour and variant 4,500 with 95 % intervals of at most ±1.5 points; 1000, "
        "as Table 1, makes it 360,000 and several minutes)."
    )
    planners: tuple[str, ...] = VARIANT_NAMES  # the paper's four, then the RSS variants
    decels: tuple[float, ...] = DECELS
    n_leaders: tuple[int, ...] = (1, 3, 10)
    followers: tuple[Follower, ...] = ("collaborative", "aggressive", "ignores_ego")

    def model_post_init(self, __context) -> None:
        for name in self.planners:
            get_variant(name)


def rss_cells(cfg: RssBaselineConfig) -> list[Cell]:
    """The cells of one follower behaviour (every behaviour runs the same cells)."""
    return [Cell(p, n, d) for n in cfg.n_leaders for d in cfg.decels for p in cfg.planners]


def run_rss_baseline(cfg: RssBaselineConfig, *, preset, seed: int, workers, nominal, cache=None):
    """``(table, summary)``: every cell under every follower behaviour. ``cache`` (see
    :func:`~safelane.experiments.grid.run_cells`) serves the collaborative behaviour only — the sampler's own F, so
    its paper-variant cells are Table 1's; the other behaviours change F and share nothing."""
    cells = rss_cells(cfg)
    length = preset.params.vehicle_length
    parts = []
    for follower in cfg.followers:
        scenario_over, sim_over = FOLLOWERS[follower]
        table = run_cells(
            cells, cfg.samples, seed, params=preset.params, config=preset.sim.model_copy(update=sim_over),
            scenario=ScenarioConfig(**scenario_over) if scenario_over else None, nominal=nominal, workers=workers,
            cache=cache if not (scenario_over or sim_over) else None,
        )  # fmt: skip
        table.insert(1, "follower", follower)
        table["collision_with_follower"] = table["collision"] & (table["min_gap_follower_m"] < length)
        table["collision_with_leader"] = table["collision"] & (table["min_gap_leader_m"] < length)
        parts.append(table)
    table = pd.concat(parts, ignore_index=True)
    summary = summarize(table, by=("follower", "planner", "n_leaders", "decel"))
    by_who = table.groupby(["follower", "planner", "n_leaders", "decel"], sort=False)
    for col in ("collision_with_follower", "collision_with_leader", "completed"):
        summary[f"{col}_rate"] = by_who[col].mean().to_numpy()
    return table, summary


def overview(summary: pd.DataFrame) -> pd.DataFrame:
    """Per follower behaviour and planner, pooled over the grid: success, collision, ``p_m`` violation rates with
    95 % Wilson intervals, and the collisions by whom the ego hit."""
    counts = summary.assign(
        **{f"{c}_k": summary[f"{c}_rate"] * summary["samples"] for c in (
            "success", "collision", "safety_violation", "collision_with_follower", "collision_with_leader")}
    )  # fmt: skip
    pooled = counts.groupby(["follower", "planner"], sort=False).sum(numeric_only=True)
    out = pd.DataFrame({"samples": pooled["samples"].astype(int)})
    for c in ("success", "collision", "safety_violation"):
        k = np.rint(pooled[f"{c}_k"].to_numpy())
        lo, hi = wilson_interval(k, out["samples"].to_numpy())
        out[f"{c}_rate"], out[f"{c}_lo"], out[f"{c}_hi"] = k / out["samples"], lo, hi
    for c in ("collision_with_follower", "collision_with_leader"):
        out[f"{c}_rate"] = np.rint(pooled[f"{c}_k"].to_numpy()) / out["samples"]
    return out.reset_index()
