"""The falsifier's report: counts, the worst scenario, replayable failure dumps, and merging parallel streams
(:mod:`safelane.experiments.falsify`)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

if TYPE_CHECKING:  # the falsifier imports this module; only the annotation needs its Setting
    from .falsify import Setting

OUTCOMES = ("collision", "safety_violation", "leader_collision", "leader_violation")
#: Counted too, not failures: the assumption monitor's verdict (inside the assumptions it should stay silent) and
#: proposals the closed loop rejected (the adversaries return finite, clipped actions). Zero where the simulator
#: has no such column.
NOTES = ("assumption_breach", "n_invalid_proposals")


@dataclass
class Report:
    """What a falsification run found (``worst``: the scenario with the smallest gap over its margin)."""

    seed: int
    methods: tuple[str, ...]
    hooks: bool
    profiles: bool
    generated: int = 0
    simulated: int = 0
    wall_s: float = 0.0
    counts: dict = field(default_factory=lambda: {name: 0 for name in (*OUTCOMES, *NOTES)})
    by_method: dict = field(default_factory=dict)
    min_ratio: float = np.inf
    min_ratio_l1: float = np.inf
    min_ratio_f: float = np.inf
    min_lane_ratio_sampled: float = np.inf
    worst: dict | None = None
    failures: list = field(default_factory=list)
    breaches: list = field(default_factory=list)  # scenarios in which the monitor flagged a breach (the first 20)

    def add(self, method: str, generated: int, outcome: pd.DataFrame, spec: dict, setting: Setting) -> None:
        self.generated += generated
        self.simulated += len(outcome)
        m = self.by_method.setdefault(method, {"generated": 0, "simulated": 0, "min_ratio": np.inf, "failures": 0})
        m["generated"] += generated
        m["simulated"] += len(outcome)
        if not len(outcome):
            return
        bad = outcome[list(OUTCOMES)].to_numpy(bool)
        for name, col in zip(OUTCOMES, bad.T, strict=True):
            self.counts[name] += int(col.sum())
        for name in NOTES:
            self.counts[name] += int(outcome[name].sum()) if name in outcome else 0
        m["failures"] += int(bad.any(1).sum())
        for i in np.flatnonzero(bad.any(1))[: max(0, 20 - len(self.failures))]:
            self.failures.append(scenario_record(spec, i, outcome.iloc[i], setting, method))
        if "assumption_breach" in outcome:  # inside the assumptions a flag is the monitor's false alarm: keep it
            flagged = np.flatnonzero(outcome["assumption_breach"].to_numpy() > 0)
            for i in flagged[: max(0, 20 - len(self.breaches))]:
                self.breaches.append(scenario_record(spec, i, outcome.iloc[i], setting, method))
        ratios = outcome["ratio"].to_numpy(float)
        self.min_ratio_l1 = float(np.fmin(self.min_ratio_l1, np.nanmin(outcome["ratio_l1"], initial=np.inf)))
        self.min_ratio_f = float(np.fmin(self.min_ratio_f, np.nanmin(outcome["ratio_f"], initial=np.inf)))
        lane = outcome["lane_ratio"].to_numpy(float)
        self.min_lane_ratio_sampled = float(np.fmin(self.min_lane_ratio_sampled, np.nanmin(lane, initial=np.inf)))
        if np.isfinite(ratios).any():
            i = int(np.nanargmin(ratios))
            m["min_ratio"] = float(min(m["min_ratio"], ratios[i]))
            if ratios[i] < self.min_ratio:
                self.min_ratio = float(ratios[i])
                self.worst = scenario_record(spec, i, outcome.iloc[i], setting, method)

    def summary(self) -> dict:
        """Everything but the scenario dumps (JSON-ready)."""
        return {
            "seed": self.seed,
            "methods": list(self.methods),
            "traffic_hooks": self.hooks,
            "last_profiles": self.profiles,
            "scenarios_generated": self.generated,
            "scenarios_simulated": self.simulated,
            "dropped_initial_state": self.generated - self.simulated,
            "wall_s": round(self.wall_s, 1),
            "collisions": self.counts["collision"],
            "p_m_violations_ego": self.counts["safety_violation"],
            "leader_collisions": self.counts["leader_collision"],
            "p_m_violations_leaders": self.counts["leader_violation"],
            "assumption_breaches_flagged": self.counts["assumption_breach"],
            "invalid_proposals": self.counts["n_invalid_proposals"],
            "min_gap_over_p_m": self.min_ratio,
            "min_gap_over_p_m_l1": self.min_ratio_l1,
            "min_gap_over_p_m_f": self.min_ratio_f,
            "min_lane_gap_over_margin_sampled": self.min_lane_ratio_sampled,
            "by_method": self.by_method,
        }

    def text(self) -> str:
        s = self.summary()
        lines = [f"{k}: {v}" for k, v in s.items() if k != "by_method"]
        for name, m in s["by_method"].items():
            lines.append(
                f"  {name}: {m['simulated']} simulated / {m['generated']} generated, min gap/p_m "
                f"{m['min_ratio']!r}, failures {m['failures']}"
            )
        return "\n".join(lines)

    def write(self, out: Path) -> list[Path]:
        """``report.json`` (summary), ``worst.json`` (replayable), ``failure_<i>.json`` for each failure,
        ``breach_<i>.json`` for each scenario in which the monitor flagged a breach (the first 20 of each)."""
        out.mkdir(parents=True, exist_ok=True)
        written = [out / "report.json"]
        written[0].write_text(json.dumps(self.summary(), indent=2, default=float) + "\n")
        dumps = ([("worst.json", self.worst)] if self.worst else []) + [
            (f"failure_{i}.json", rec) for i, rec in enumerate(self.failures)
        ] + [(f"breach_{i}.json", rec) for i, rec in enumerate(self.breaches)]
        for name, rec in dumps:
            (out / name).write_text(json.dumps(rec, indent=1) + "\n")
            written.append(out / name)
        return written


def scenario_record(spec: dict, i: int, outcome_row, setting: Setting, method: str) -> dict:
    """One scenario, replayable with :func:`replay`: its spec row, the setting, and what happened."""
    return {
        "method": method,
        "seed": setting.seed,
        "params": setting.params.model_dump(),
        "sim": setting.sim.model_dump(),
        "decel_last_max": setting.decel_last_max,
        "use_hooks": setting.use_hooks,
        "use_profiles": setting.use_profiles,
        "spec": {k: np.asarray(v[i]).tolist() for k, v in spec.items()},
        "outcome": {k: json_scalar(v) for k, v in outcome_row.items() if k != "row"},
    }


def json_scalar(value):
    """A JSON-ready scalar: NumPy scalars as Python ones, NaN (no such gap) as None."""
    value = value.item() if hasattr(value, "item") else value
    return None if isinstance(value, float) and np.isnan(value) else value


def merge(reports: list[Report]) -> Report:
    """One report of several streams: counts add up, minima are taken, the worst scenario is the overall worst."""
    out = Report(seed=reports[0].seed, methods=reports[0].methods, hooks=reports[0].hooks, profiles=reports[0].profiles)
    for r in reports:
        out.generated += r.generated
        out.simulated += r.simulated
        out.wall_s = max(out.wall_s, r.wall_s)
        for name in (*OUTCOMES, *NOTES):
            out.counts[name] += r.counts[name]
        for name, m in r.by_method.items():
            acc = out.by_method.setdefault(name, {"generated": 0, "simulated": 0, "min_ratio": np.inf, "failures": 0})
            for key in ("generated", "simulated", "failures"):
                acc[key] += m[key]
            acc["min_ratio"] = min(acc["min_ratio"], m["min_ratio"])
        out.min_ratio_l1 = min(out.min_ratio_l1, r.min_ratio_l1)
        out.min_ratio_f = min(out.min_ratio_f, r.min_ratio_f)
        out.min_lane_ratio_sampled = min(out.min_lane_ratio_sampled, r.min_lane_ratio_sampled)
        if r.min_ratio < out.min_ratio:
            out.min_ratio, out.worst = r.min_ratio, r.worst
        out.failures.extend(r.failures[: max(0, 20 - len(out.failures))])
        out.breaches.extend(r.breaches[: max(0, 20 - len(out.breaches))])
    return out
