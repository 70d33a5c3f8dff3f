"""Build ``report.md`` and the self-contained ``report.html`` of a reproduction run.

The report answers "does it reproduce the paper, and how close?": a headline, Table 1 beside the paper's numbers
(with the mean absolute difference over the published cells and our N = 3 prediction), every claim with its
verdict and numbers, the figures, compact per-experiment tables, the calibration behind the preset, wall times,
software versions, the seed and the command line.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from ..experiments.paper_data import PLANNERS, PUBLISHED_N
from ..experiments.registry import EXPERIMENTS
from ..shield import ABORT
from .document import Document

if TYPE_CHECKING:
    from ..experiments.calibration import Preset
    from ..experiments.claims import Claim
    from ..experiments.runner import ExperimentResult

TITLE = "Reproduction: Connectivity Enhanced Safe Neural Network Planner for Lane Changing in Mixed Traffic"
#: Experiment -> (rows, columns, rates) of its compact tables in the report (Table 1 has its own section).
PIVOTS: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "fig4_n5": ("decel", "planner", ("success",)),
    "fig6_violation": ("p_v", "decel", ("collision", "success")),
    "penetration": ("penetration", "planner", ("success",)),
    "leaders": ("n_leaders", "planner", ("success",)),
}
_VERDICT = {True: "**holds**", False: "**does not hold**", None: "not checked"}


@dataclass
class RunRecord:
    """Everything a report says about one run of :func:`safelane.experiments.reproduce.reproduce`."""

    run_id: str
    run_dir: Path
    seed: int
    quick: bool
    command: str
    preset: Preset
    results: dict[str, ExperimentResult]
    claims: list[Claim]
    side_by_side: pd.DataFrame | None
    mae: float | None
    figures: dict[str, list[Path]]
    data_files: list[Path]
    versions: dict[str, str]
    parquet: bool
    timings: dict[str, float]  # experiment -> seconds, plus "figures and files"
    started_utc: str


def write_report(record: RunRecord) -> tuple[Path, Path]:
    """Write ``report.md`` and ``report.html`` into ``record.run_dir``; returns their paths."""
    doc = build_document(record)
    md, page = record.run_dir / "report.md", record.run_dir / "report.html"
    md.write_text(doc.to_markdown(), encoding="utf-8")
    page.write_text(doc.to_html(), encoding="utf-8")
    return md, page


def build_document(r: RunRecord) -> Document:
    doc = Document(TITLE)
    doc.paragraph(_headline(r))
    doc.bullets(
        [
            f"Run `{r.run_id}`, started {r.started_utc} UTC; seed **{r.seed}**; "
            f"{'**quick** (reduced) grid' if r.quick else 'full grid (paper defaults)'}; preset `{r.preset.name}`; "
            f"nominal planner in the loop: {_nominal_label(r.preset)}.",
            f"Command: `{r.command}`",
            f"Total wall time {sum(r.timings.values()):.1f} s.",
        ]
    )
    if r.side_by_side is not None:
        _table1(doc, r.side_by_side, r.mae)
    _claims(doc, r.claims)
    _figures(doc, r)
    _experiments(doc, r)
    _calibration(doc, r.preset)
    _timings(doc, r)
    doc.heading(1, "Software")
    doc.table(["package", "version"], [[k, v] for k, v in r.versions.items()])
    doc.heading(1, "Files")
    parquet = "CSV and Parquet" if r.parquet else "CSV only (pyarrow is not installed, so Parquet was skipped)"
    doc.paragraph(f"Tidy per-scenario tables and per-cell summaries, {parquet}; timings are kept out of the tables.")
    doc.bullets([f"[{p.as_posix()}]({p.as_posix()})" for p in r.data_files])
    return doc


def _headline(r: RunRecord) -> str:
    checked = [c for c in r.claims if c.holds is not None]
    held = [c for c in checked if c.holds]
    parts = []
    if r.mae is not None:
        parts.append(f"Table 1: mean absolute difference **{r.mae:.3f}** to the paper's published N = 1 and 10 cells")
    parts.append(f"**{len(held)} of {len(checked)}** checked claims hold")
    failed = [c.key for c in checked if not c.holds]
    if failed:
        parts.append("not holding: " + ", ".join(f"`{k}`" for k in failed))
    if r.quick:
        parts.append("quick grid: few samples per cell, so intervals are wide")
    return "**Headline.** " + "; ".join(parts) + "."


def _f(x, fmt: str = ".3f") -> str:
    return "—" if x is None or pd.isna(x) else format(float(x), fmt)


def _table1(doc: Document, frame: pd.DataFrame, mae: float | None) -> None:
    doc.heading(1, "Table 1 side by side")
    planners = [p for p in PLANNERS if p in set(frame["planner"])]
    cell = frame.set_index(["n_leaders", "decel", "planner"])
    published = frame[frame["n_leaders"].isin(PUBLISHED_N)]
    if len(published):
        n_cells = int(published["paper_success"].notna().sum())
        doc.paragraph(
            f"Success rates, ours beside the paper's, Δ = ours − paper. Mean absolute difference over the "
            f"{n_cells} published cells: **{_f(mae)}**."
        )
        header = ["N", "a [m/s²]"] + [h for p in planners for h in (f"{p} ours", "paper", "Δ")]
        rows = []
        for (n, d), _ in published.groupby(["n_leaders", "decel"], sort=True):
            row = [n, f"{d:g}"]
            for p in planners:
                c = cell.loc[(n, d, p)]
                row += [_f(c["success_rate"]), _f(c["paper_success"]), _f(c["diff"], "+.3f")]
            rows.append(row)
        doc.table(header, rows)
    predicted = frame[~frame["n_leaders"].isin(PUBLISHED_N)]
    if len(predicted):
        doc.heading(2, "Our prediction for N = 3 (a prediction: the paper's N = 3 rows are withheld, never fitted)")
        rows = []
        for (n, d), _ in predicted.groupby(["n_leaders", "decel"], sort=True):
            row = [n, f"{d:g}"]
            for p in planners:
                c = cell.loc[(n, d, p)]
                row.append(f"{_f(c['success_rate'])} [{_f(c['success_lo'])}, {_f(c['success_hi'])}]")
            rows.append(row)
        doc.table(["N", "a [m/s²]"] + [f"{p} (95 % CI)" for p in planners], rows)


def _claims(doc: Document, claims: list[Claim]) -> None:
    doc.heading(1, "The paper's claims")
    doc.paragraph(
        "A reversal or trend counts only beyond sampling noise: where the 95 % Wilson intervals do not overlap."
    )
    doc.table(
        ["claim", "statement", "verdict", "evidence"],
        [[f"`{c.key}`", c.text, _VERDICT[c.holds], c.evidence] for c in claims],
    )


def _figures(doc: Document, r: RunRecord) -> None:
    doc.heading(1, "Figures")
    for name, paths in r.figures.items():
        png = next(p for p in paths if p.suffix == ".png")
        svg = next((p for p in paths if p.suffix == ".svg"), None)
        doc.heading(2, name)
        doc.image(png, png.relative_to(r.run_dir).as_posix(), EXPERIMENTS[name].description)
        if svg is not None:
            doc.paragraph(f"Vector version: [{svg.name}]({svg.relative_to(r.run_dir).as_posix()})")


def _experiments(doc: Document, r: RunRecord) -> None:
    doc.heading(1, "Experiments")
    for name, res in r.results.items():
        doc.heading(2, name)
        doc.paragraph(EXPERIMENTS[name].description)
        doc.paragraph(f"Config: `{json.dumps(res.config.model_dump(mode='json'), separators=(',', ':'))}`")
        if res.trace is not None:
            _trace_table(doc, res.trace)
        if name in PIVOTS and res.summary is not None:
            _pivots(doc, res.summary, *PIVOTS[name])
        if name == "rss_baseline" and res.summary is not None:
            from .rss import section  # the RSS baseline's table and paragraph (docs/rss.md)

            section(doc, res.summary)
        if name == "table1_safe_mode" and res.summary is not None and "table1" in r.results:
            from .modes import section as modes_section  # paper-faithful vs safe mode (issue 12)

            modes_section(doc, r.results["table1"].summary, res.summary)
        if name == "table1_rules" and res.summary is not None and "table1" in r.results:
            from .modes import nn_section  # the reported (NN) Table 1 beside the rule-based planner's (issue 12)

            nn_section(doc, r.results["table1"].summary, res.summary)


def _nominal_label(preset) -> str:
    network = getattr(preset, "network", None)
    if network:
        return f"`{network}` (the network distilled from the preset's rule-based planner; `table1_rules` runs that)"
    return "the preset's rule-based planner"


def _pivots(doc: Document, summary: pd.DataFrame, rows_key: str, cols_key: str, rates: tuple[str, ...]) -> None:
    """One compact table per rate: ``rows_key`` down, ``cols_key`` across."""
    for rate in rates:
        pivot = summary.pivot_table(index=rows_key, columns=cols_key, values=f"{rate}_rate", sort=True)
        if cols_key == "planner":
            pivot = pivot[[p for p in PLANNERS if p in pivot.columns]]
        header = [f"{rate} rate: {rows_key} \\ {cols_key}"] + [_label(c) for c in pivot.columns]
        rows = [[_label(i)] + [_f(v) for v in row] for i, row in zip(pivot.index, pivot.to_numpy(), strict=True)]
        doc.table(header, rows)


def _label(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _trace_table(doc: Document, trace: pd.DataFrame) -> None:
    """Per planner: whether and when the lane change completes, or when the ego aborts and turns back."""
    rows = []
    for planner in [p for p in PLANNERS if p in set(trace["planner"])]:
        t = trace[trace["planner"] == planner].sort_values("t")
        done, aborts, before = t[t["completed"]], t[t["behaviour"] == ABORT], t[~t["completed"]]
        peak = before.loc[before["ego_y"].idxmax()] if len(before) else None
        rows.append(
            [
                planner,
                _f(done["t"].iloc[0], ".1f") if len(done) else "never",
                _f(aborts["t"].iloc[0], ".1f") if len(aborts) else "never",
                "—" if peak is None or len(done) else _f(peak["t"], ".1f"),
                "—" if peak is None else _f(peak["ego_y"], ".2f"),
                _f(t["ego_vx"].min(), ".1f"),
                "yes" if t["collided"].any() else "no",
            ]
        )
    header = [
        "planner",
        "completes at [s]",
        "first abort at [s]",
        "turns back at [s]",
        "max y before completion [m]",
        "min v_x [m/s]",
        "collision",
    ]
    doc.table(header, rows)


def _calibration(doc: Document, preset: Preset) -> None:
    doc.heading(1, f"Calibration (preset `{preset.name}`)")
    meta = preset.meta or {}
    values = {
        **preset.params.model_dump(),
        **{f"sim.{k}": v for k, v in preset.sim.model_dump().items()},
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
                row.append("—" if c is None else f"{_f(c['success_rate'])} / {_f(c['paper_success'])}")
            rows.append(row)
        doc.paragraph("Fit per cell at calibration time (ours / paper):")
        doc.table(["N", "a [m/s²]", *planners], rows)


def _timings(doc: Document, r: RunRecord) -> None:
    doc.heading(1, "Wall time")
    rows = []
    for name, res in r.results.items():
        n_cells = 1 if res.summary is None else len(res.summary)
        scenarios = len(res.table) if res.table is not None else res.trace["planner"].nunique()
        rows.append([name, n_cells, scenarios, _f(r.timings[name], ".2f")])
    rows += [[k, "", "", _f(v, ".2f")] for k, v in r.timings.items() if k not in r.results]
    rows.append(["**total**", "", "", f"**{sum(r.timings.values()):.2f}**"])
    doc.table(["step", "cells", "scenarios", "seconds"], rows)
