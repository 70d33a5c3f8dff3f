"""The report's calibration section: the preset's settings and how they were fitted."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pandas as pd

from ..experiments.paper_data import PLANNERS
from .document import Document
from .prose import number

if TYPE_CHECKING:
    from ..experiments.calibration import Preset


def calibration_section(doc: Document, preset: Preset) -> None:
    """The report's section on the preset: every setting (a nested one as ``sim.shield.x``), its calibration record
    and the fit per cell at calibration time."""
    doc.heading(1, f"Calibration (preset `{preset.name}`)")
    meta = preset.meta or {}
    values = {
        **preset.params.model_dump(),
        **{f"sim.{k}": v for k, v in _flat(preset.sim.model_dump()).items()},
        **{f"planner.{k}": v for k, v in getattr(preset, "planner", {}).items()},
        "nominal planner in the loop": getattr(preset, "network", None) or "the rule-based planner above",
    }
    doc.table(["setting", "value"], [[k, v] for k, v in values.items()])
    if not meta:
        doc.paragraph("This preset carries no calibration record.")
        return
    keys = ("loss_mean_abs_diff", "fitted_to", "procedure", "seed")
    notes = [f"{k.replace('_', ' ')}: {meta[k]}" for k in keys if k in meta]
    if "command" in meta:
        notes.append(f"command: `{meta['command']}`")
    doc.bullets(notes)
    if meta.get("search_space"):
        doc.paragraph("Search space (see `safelane.experiments.calibration` for why these ranges):")
        doc.table(["parameter", "low", "high"], [[k, *v] for k, v in meta["search_space"].items()])
    if meta.get("per_cell"):
        fit = pd.DataFrame(meta["per_cell"])
        planners = [p for p in PLANNERS if p in set(fit["planner"])]
        cell = fit.set_index(["n_leaders", "decel", "planner"])
        rows = []
        for (n, d), _ in fit.groupby(["n_leaders", "decel"], sort=True):
            row = [n, f"{d:g}"]
            for p in planners:
                c = cell.loc[(n, d, p)] if (n, d, p) in cell.index else None
                row.append("—" if c is None else f"{number(c['success_rate'])} / {number(c['paper_success'])}")
            rows.append(row)
        doc.paragraph("Fit per cell at calibration time (ours / paper):")
        doc.table(["N", "a [m/s²]", *planners], rows)


def _flat(settings: dict, prefix: str = "") -> dict:
    """Nested settings as ``{"shield.assessment": ...}`` (one table row each)."""
    out = {}
    for key, value in settings.items():
        out.update(_flat(value, f"{prefix}{key}.") if isinstance(value, dict) else {prefix + key: value})
    return out
