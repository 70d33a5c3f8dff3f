"""Closed loop: DAgger state collection and closed-loop evaluation of nominal planners in the simulator.

DAgger (Ross et al., 2011): a network trained on sampled states drifts, in closed loop, into states the sampler
rarely draws (e.g. hesitating at the lane boundary while the gap closes). Each round runs the current network as
the nominal planner of :func:`safelane.sim.simulate` over the configured experiment cells, records the states it
visits, labels a random subset with the teacher and retrains on the union.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field

from ..params import Params
from ..planners.base import NominalPlanner, Observation
from ..sim import SimConfig, simulate
from .data import concat_observations, take


class SimCell(BaseModel):
    """One experiment cell of the simulator: planner variant, connected leaders ``N``, ``a_x,N+1,d`` [m/s²]."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    variant: str = Field("CV_all", description="Planner variant (safelane.planners.variants).")
    n_leaders: int = Field(3, ge=1, description="Connected leaders N.")
    decel: float = Field(4.0, ge=0.0, description="Sudden deceleration of L(N+1) [m/s²].")


def _default_cells() -> list[SimCell]:
    return [SimCell(variant="CV_all", n_leaders=n, decel=d) for n in (1, 5, 10) for d in (2.0, 4.0, 6.0)]


class DaggerConfig(BaseModel):
    """DAgger rounds after the initial fit (0 = none)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    rounds: int = Field(0, ge=0, description="DAgger rounds.")
    cells: list[SimCell] = Field(default_factory=_default_cells, description="Cells simulated in each round.")
    scenarios_per_cell: int = Field(100, ge=1, description="Scenarios simulated per cell and round.")
    states_per_round: int = Field(20_000, ge=1, description="Visited states labelled and added per round.")
    epochs_per_round: int = Field(40, ge=1, description="Maximum training epochs after each round.")
    horizon_s: float = Field(10.0, gt=0.0, description="Simulated time per scenario [s].")


class EvalConfig(BaseModel):
    """Closed-loop evaluation after training (written to ``closed_loop.csv``; empty ``cells`` = none)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    cells: list[SimCell] = Field(default_factory=list, description="Cells to evaluate.")
    samples: int = Field(200, ge=1, description="Scenarios per cell.")
    seed: int = Field(12345, ge=0, description="Scenario seed (distinct from DAgger's seeds).")
    baselines: list[Literal["expert", "teacher"]] = Field(["expert"], description="Also evaluate these planners.")


def collect_states(
    planner: NominalPlanner,
    cfg: DaggerConfig,
    params: Params,
    rng: np.random.Generator,
    seed: int,
    n_states: int | None = None,
) -> Observation:
    """States visited in closed loop by ``planner`` (as the nominal planner) over ``cfg.cells``; a uniform random
    subset of ``n_states`` (default ``cfg.states_per_round``) drawn with ``rng``. ``seed`` seeds the scenarios."""
    sim_cfg = SimConfig(horizon_s=cfg.horizon_s)
    batches = []
    for j, cell in enumerate(cfg.cells):
        res = simulate(
            planner=cell.variant,
            n_leaders=cell.n_leaders,
            decel=cell.decel,
            samples=cfg.scenarios_per_cell,
            seed=seed + j,
            params=params,
            config=sim_cfg,
            nominal=planner,
            record_observations=True,
        )
        batches.extend(res.observations)
    visited = concat_observations(batches)
    n = len(visited.p_x)
    want = min(n_states or cfg.states_per_round, n)
    return take(visited, np.sort(rng.choice(n, size=want, replace=False)))


def evaluate_closed_loop(
    planners: dict[str, NominalPlanner], cells: list[SimCell], samples: int, seed: int, params: Params | None = None
) -> pd.DataFrame:
    """One row per (planner, cell): success / collision / safety-violation rates, mean completion time [s] of the
    completed scenarios, mean hesitate / abort periods. Every planner sees the same scenarios (same seed)."""
    rows = []
    for name, planner in planners.items():
        for j, cell in enumerate(cells):
            t = simulate(
                planner=cell.variant, n_leaders=cell.n_leaders, decel=cell.decel, samples=samples,
                seed=seed + j, params=params, nominal=planner,
            ).table
            rows.append({
                "nominal": name, "variant": cell.variant, "n_leaders": cell.n_leaders, "decel": cell.decel,
                "samples": samples, "success": t["success"].mean(), "collision": t["collision"].mean(),
                "safety_violation": t["safety_violation"].mean(),
                "completion_time_s": t["completion_time_s"].mean(),
                "n_hesitate": t["n_hesitate"].mean(), "n_abort": t["n_abort"].mean(),
            })
    return pd.DataFrame(rows)
