"""What a simulation run returns: the per-scenario table, the optional trace and recorded observations."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..planners.base import Observation
from ..planners.variants import VARIANT_NAMES
from ..shield.monitor import BREACH_KINDS
from . import blame_log
from .scenario import ScenarioBatch

if TYPE_CHECKING:  # pandas loads with the first table, not with the package
    import pandas as pd


@dataclass
class SimResult:
    """Per-scenario table, optional per-step trace and recorded observations.

    ``preset`` and ``nominal`` name the run's preset (``None``: none) and nominal planner (``"mlp_paper"``,
    ``"expert (preset gains)"``, a model file's path, ...); :func:`~safelane.sim.simulate` sets them."""

    table: pd.DataFrame
    trace: pd.DataFrame | None = None
    observations: list[Observation] = field(default_factory=list)
    preset: str | None = None
    nominal: str | None = None
    #: Which engine ran it: ``"compiled loop"`` (sim/_fused.py), ``"compiled period"`` (the periods compiled, the
    #: nominal planner, the trace or the observations between them: ``sim/_stepper.Stepper``), ``"period by period"``
    #: (with ``engine_reasons``, why the compiled loop did not take it), or ``None`` (split over workers).
    engine: str | None = None
    engine_reasons: tuple = ()

    def summary(self) -> pd.DataFrame:
        """One row per cell: rates with 95 % Wilson intervals (:func:`~.metrics.summarize`), after the columns
        ``preset`` and ``nominal`` where the run recorded them (a result of :func:`~safelane.sim.simulate` does):
        the same cell gives different numbers under another nominal planner."""
        from .metrics import summarize

        out = summarize(self.table)
        if "collision_blame" in self.table.columns:  # recorded (simulate(..., blame=True)): beside each total
            _ego_responsible(self.table, out)
        if self.nominal is not None:
            out.insert(0, "nominal", self.nominal)
            out.insert(0, "preset", self.preset)
        return out


def _ego_responsible(table: pd.DataFrame, out: pd.DataFrame) -> None:
    """Insert ``collision_ego_rate`` / ``safety_violation_ego_rate`` (the share of the cell's scenarios whose first
    collision / ``p_m`` violation the blame rule puts on the ego, alone or with the other) after each total's
    interval, in ``out``'s cell order."""
    by = [c for c in ("planner", "n_leaders", "decel", "p_v") if c in table.columns]
    for total, blamed in (("collision", "collision_blame"), ("safety_violation", "pm_blame")):
        ego = table[blamed].isin(["ego", "both"]).groupby([table[c] for c in by], sort=False).mean()
        rate = out.set_index(by).index.map(ego.to_dict()) if len(by) > 1 else out[by[0]].map(ego)
        out.insert(out.columns.get_loc(f"{total}_hi") + 1, f"{total}_ego_rate", np.asarray(rate, float))


def results_table(b: ScenarioBatch, s) -> pd.DataFrame:
    """One row per scenario: outcomes, gaps, behaviour counts, assessment."""
    import pandas as pd

    truth = b.follower_aggressive
    belief = s.belief.aggressive
    return pd.DataFrame(
        {
            "scenario_id": b.scenario_id,
            "planner": np.asarray(VARIANT_NAMES)[b.variant],
            "n_leaders": b.n_connected,
            "decel": b.decel_last,
            "p_v": b.p_v,
            "success": s.completed & ~s.collided,
            "collision": s.collided,
            "safety_violation": s.violated,
            "leader_collision": s.leader_collided,
            "leader_violation": s.leader_violated,
            "completed": s.completed,
            "completion_time_s": s.t_complete,
            "min_gap_follower_m": np.where(np.isinf(s.min_gap_f), np.nan, s.min_gap_f),
            "min_gap_leader_m": np.where(np.isinf(s.min_gap_l1), np.nan, s.min_gap_l1),
            "min_lane_gap_ratio": np.where(np.isinf(s.min_lane_ratio), np.nan, s.min_lane_ratio),
            "n_proceed": s.counts[:, 0],
            "n_hesitate": s.counts[:, 1],
            "n_abort": s.counts[:, 2],
            "follower_connected": b.connected[:, 0],
            "follower_aggressive": truth,
            "assessed_aggressive": belief,
            "assessment_correct": belief == truth,
            "assessment_time_s": s.belief.first_collaborative_s,
            "n_invalid_proposals": s.n_invalid,
            "assumption_breach": s.breach.any,
            "breach_time_s": s.breach.first_s,
            **{f"breach_{kind}": s.breach.flags[:, i] for i, kind in enumerate(BREACH_KINDS)},
            "initial_safe": s.initial_safe,
            **_own_lane_columns(s),
            **({} if getattr(s, "blame", None) is None else blame_log.columns(s.blame)),
        }
    )


def _own_lane_columns(s) -> dict:
    """With an own-lane leader L0 (docs/real_roads.md): the ego's collisions / violations against it (also counted in
    ``collision`` / ``safety_violation``) and the smallest gap."""
    if getattr(s, "l0", None) is None:
        return {}
    gap = s.min_gap_l0
    out = {"own_lane_collision": s.l0_collided, "own_lane_violation": s.l0_violated,
           "min_gap_own_lane_m": np.where(np.isinf(gap), np.nan, gap)}  # fmt: skip
    if s.l0[0].shape[1] > 1:  # a chain: did its vehicles keep clear of each other (the traffic's own soundness)
        out["own_lane_leader_collision"] = s.own_pair_collided
    return out


def trace_rows(b: ScenarioBatch, s, behaviour, limit: int) -> pd.DataFrame:
    """Per-step rows of the first ``limit`` scenarios."""
    import pandas as pd

    n = min(limit, len(b))
    ex, ey, evx, evy = s.ego
    return pd.DataFrame(
        {
            "scenario_id": b.scenario_id[:n],
            "planner": np.asarray(VARIANT_NAMES)[b.variant[:n]],
            "t": s.t if np.ndim(s.t) == 0 else s.t[:n],  # (the compiled loop's state: each row's clock)
            "ego_x": ex[:n],
            "ego_y": ey[:n],
            "ego_vx": evx[:n],
            "ego_vy": evy[:n],
            "behaviour": behaviour[:n],
            "f_x": s.x[:n, 0],
            "f_v": s.v[:n, 0],
            "l1_x": s.x[:n, 1],
            "l1_v": s.v[:n, 1],
            "completed": s.completed[:n],
            "violated": s.violated[:n],
            "collided": s.collided[:n],
        }
    )
