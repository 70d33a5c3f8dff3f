"""Build ``report.md`` and the self-contained ``report.html`` of a reproduction run.

The report answers "does it reproduce the paper, and how close?": a headline, Table 1 beside the paper's numbers
(with the mean absolute difference over the published cells and our N = 3 prediction), every claim with its
verdict and numbers, one section per experiment (its figure, compact tables and what they say), the calibration
behind the preset, wall times, software versions, the seed and the command line; a table of contents after the
headline.

Every sentence that states a number or a comparison is assembled from the table it describes: the comparison
words, signs and "with"/"without" come from :mod:`safelane.reporting.prose`, never from a fixed template.
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
from . import prose
from .calibration_section import calibration_section
from .document import Document
from .prose import number as _f

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

#: Experiment -> (human title, what it shows). The grid behind it (N, braking, planners, samples…) is stated from
#: the results by :func:`grid_sentence`, so these texts carry no number that could drift from the data.
TITLES: dict[str, tuple[str, str]] = {
    "fig4_n5": ("Fig. 4: success vs the last leader's sudden braking",
                "Success rate against the sudden deceleration of the last connected leader, one line per planner "
                "(cf. paper Fig. 4)."),
    "table1": ("Table 1: success for every N, braking and planner",
               "Success rate per number of connected leaders N, one panel each; ours as lines with 95 % intervals, "
               "the paper's published values as crosses (cf. paper Table 1)."),
    "fig5_example": ("Fig. 5: one lane change under every planner",
                     "One scenario traced under every planner: the ego's lateral position and speed over time "
                     "(cf. paper Fig. 5)."),
    "fig6_violation": ("Fig. 6: robustness to broken promises",
                       "Collision and success rate against the sudden braking, one line per promise-violation rate "
                       "p_v (cf. paper Fig. 6)."),
    "penetration": ("Beyond the paper: share of connected vehicles",
                    "Success rate against the share of connected vehicles, placed at random, one line per planner."),
    "leaders": ("Beyond the paper: number of connected leaders",
                "Success rate against the number of connected leaders N, one line per planner."),
    "rss_baseline": ("Baseline: RSS against the paper's shield",
                     "RSS (ad-rss's model) against the paper's shield, with and without V2X, for three behaviours of "
                     "the follower F (collaborative, aggressive, ignoring the ego); rates pooled over the grid "
                     "(docs/rss.md)."),
    "table1_safe_mode": ("Safe mode beside the paper-faithful mode",
                         "The published Table 1 cells in safe mode (commit guard, worst-case leaders, monitor on) "
                         "beside the paper-faithful preset's (safelane.experiments.modes)."),
    "table1_rules": ("The network beside the rule-based planner it imitates",
                     "Table 1 with the rule-based planner the network is distilled from (the preset's expert), beside "
                     "the reported Table 1, which runs the network (safelane.experiments.rules_table)."),
}  # fmt: skip
#: Column -> its name in the report's tables and sentences.
AXIS_LABELS = {"decel": "braking a [m/s²]", "n_leaders": "N", "p_v": "p_v", "penetration": "penetration",
               "planner": "planner", "follower": "F"}  # fmt: skip

#: Column -> (its symbol, its unit) in sentences.
_PROSE = {"decel": ("a_x,N+1,d", " m/s²"), "n_leaders": ("N", ""), "p_v": ("p_v", ""),
          "penetration": ("penetration", ""), "follower": ("F", "")}  # fmt: skip


def title(name: str) -> str:
    """The human title of an experiment's section and figure (the id itself for one without a title)."""
    return TITLES[name][0] if name in TITLES else name.replace("_", " ").capitalize()


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
    doc.contents()
    if r.side_by_side is not None:
        _table1(doc, r.side_by_side, r.mae)
    _claims(doc, r.claims)
    _experiments(doc, r)
    calibration_section(doc, r.preset)
    _timings(doc, r)
    doc.heading(1, "Software")
    doc.table(["package", "version"], [[k, v] for k, v in r.versions.items()])
    doc.heading(1, "Files")
    parquet = "CSV and Parquet" if r.parquet else "CSV only (pyarrow is not installed, so Parquet was skipped)"
    doc.paragraph(f"Tidy per-scenario tables and per-cell summaries, {parquet}; timings are kept out of the tables.")
    doc.bullets([_file_item(p, r) for p in r.data_files])
    return doc


def _file_item(path: Path, r: RunRecord) -> str:
    """A link to a data file, or, where the folder does not hold it (a published copy), how to get it."""
    if (r.run_dir / path).exists():
        return f"[{path.as_posix()}]({path.as_posix()})"
    return f"{path.as_posix()} — not committed (per-scenario, large): `safelane reproduce --seed {r.seed}` writes it"


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


def _table1(doc: Document, frame: pd.DataFrame, mae: float | None) -> None:
    doc.heading(1, "Table 1: ours beside the paper's")
    planners = [p for p in PLANNERS if p in set(frame["planner"])]
    cell = frame.set_index(["n_leaders", "decel", "planner"])
    published = frame[frame["n_leaders"].isin(PUBLISHED_N)]
    if len(published):
        n_cells = int(published["paper_success"].notna().sum())
        doc.paragraph(
            f"Success rates, ours beside the paper's, Δ = ours − paper. Mean absolute difference over the "
            f"{n_cells} published cells: **{_f(mae)}**. " + table1_sentence(published)
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


def table1_sentence(published: pd.DataFrame) -> str:
    """Where ours and the paper's differ most, and on which side, from the side-by-side's published rows."""
    d = published.dropna(subset=["diff"])
    if d.empty:
        return ""
    worst = d.loc[d["diff"].abs().idxmax()]
    above, below = int((d["diff"] > 0).sum()), int((d["diff"] < 0).sum())
    side = "above" if worst["diff"] > 0 else "below" if worst["diff"] < 0 else "equal to"
    return (
        f"The largest difference is {_f(abs(worst['diff']))} ({worst['planner']}, N = {worst['n_leaders']}, "
        f"a = {worst['decel']:g} m/s², ours {side} the paper's); ours is above the paper in "
        f"{prose.plural(above, 'cell')}, below in {below} and equal in {len(d) - above - below}."
    )


def claims_sentence(claims: list[Claim]) -> str:
    """How many claims hold, fail and could not be checked."""
    checked = [c for c in claims if c.holds is not None]
    held = sum(bool(c.holds) for c in checked)
    text = f"{held} of {len(checked)} checked claims hold"
    if len(checked) - held:
        text += f", {len(checked) - held} {'does' if len(checked) - held == 1 else 'do'} not"
    unchecked = len(claims) - len(checked)
    if unchecked:
        text += f"; {unchecked} could not be checked with the experiments that ran"
    return text + "."


def _claims(doc: Document, claims: list[Claim]) -> None:
    doc.heading(1, "The paper's claims")
    doc.paragraph(
        claims_sentence(claims) + " A reversal or trend counts only beyond sampling noise: where the 95 % Wilson "
        "intervals do not overlap."
    )
    doc.table(
        ["claim", "statement", "verdict", "evidence"],
        [[f"`{c.key}`", c.text, _VERDICT[c.holds], c.evidence] for c in claims],
    )


def grid_sentence(name: str, res: ExperimentResult) -> str:
    """The grid behind an experiment's figure and tables, read from its results (not from a description)."""
    frame = res.summary
    if frame is None or frame.empty:
        cfg = res.config.model_dump()
        trace = res.trace if res.trace is not None else pd.DataFrame({"planner": []})
        planners = list(dict.fromkeys(trace["planner"]))
        where = ", ".join(f"{_PROSE[k][0]} = {cfg[k]:g}{_PROSE[k][1]}" for k in ("n_leaders", "decel") if k in cfg)
        return f"{where}; {prose.plural(len(planners), 'planner')}: {', '.join(planners)}."
    parts = []
    for key in ("follower", "n_leaders", "decel", "p_v", "penetration"):
        name, unit = _PROSE[key]
        if key in frame and frame[key].nunique() > 1:
            parts.append(f"{name} ∈ {{{', '.join(_label(v) for v in sorted(frame[key].unique()))}}}{unit}")
        elif key in frame and (key != "p_v" or frame[key].iloc[0] != 0):
            parts.append(f"{name} = {_label(frame[key].iloc[0])}{unit}")
    planners = [p for p in dict.fromkeys(frame["planner"])]
    samples = sorted(frame["samples"].unique())
    per_cell = f"{samples[0]}" if len(samples) == 1 else f"{samples[0]}–{samples[-1]}"
    return (
        f"Grid: {'; '.join(parts)}; {prose.plural(len(planners), 'planner')} ({', '.join(planners)}); "
        f"{per_cell} scenarios per cell, {prose.plural(len(frame), 'cell')}, {int(frame['samples'].sum())} "
        "scenarios in all; rates with 95 % Wilson intervals."
    )


def _experiments(doc: Document, r: RunRecord) -> None:
    """One section per experiment: what it shows, its grid (from the results), the figure, tables and prose."""
    doc.heading(1, "Results by experiment")
    for name, res in r.results.items():
        doc.heading(2, title(name))
        what = TITLES[name][1] if name in TITLES else EXPERIMENTS[name].description
        caption = f"{what} {grid_sentence(name, res)}"
        paths = r.figures.get(name, [])
        png = next((p for p in paths if p.suffix == ".png"), None)
        svg = next((p for p in paths if p.suffix == ".svg"), None)
        if png is not None:
            doc.image(png, png.relative_to(r.run_dir).as_posix(), caption, alt=title(name))
        else:
            doc.paragraph(caption)
        vector = "" if svg is None else f"; vector figure [{svg.name}]({svg.relative_to(r.run_dir).as_posix()})"
        doc.paragraph(f"Experiment `{name}`{vector}.")
        if res.trace is not None:
            _trace_table(doc, res.trace)
        if name in PIVOTS and res.summary is not None:
            _pivots(doc, res.summary, *PIVOTS[name])
        if name == "rss_baseline" and res.summary is not None:
            from .rss import section  # the RSS baseline's table and paragraph (docs/rss.md)

            section(doc, res.summary)
        if name == "table1_safe_mode" and res.summary is not None and "table1" in r.results:
            from .modes import section as modes_section  # paper-faithful vs safe mode

            modes_section(doc, r.results["table1"].summary, res.summary)
        if name == "table1_rules" and res.summary is not None and "table1" in r.results:
            from .modes import nn_section  # the reported (NN) Table 1 beside the rule-based planner's

            nn_section(doc, r.results["table1"].summary, res.summary)
        doc.paragraph(f"Config: `{json.dumps(res.config.model_dump(mode='json'), separators=(',', ':'))}`")


def _nominal_label(preset) -> str:
    network = getattr(preset, "network", None)
    from ..planners.registry import is_model_path

    if network and is_model_path(network):
        return (f"`{network}` (a model file given with `--nominal`; the section “{title('table1_rules')}” runs the "
                "preset's rule-based planner)")  # fmt: skip
    if network:
        return (
            f"`{network}` (the network distilled from the preset's rule-based planner; the section "
            f"“{title('table1_rules')}” runs that planner)"
        )
    return "the preset's rule-based planner"


def _pivots(doc: Document, summary: pd.DataFrame, rows_key: str, cols_key: str, rates: tuple[str, ...]) -> None:
    """One compact table per rate: ``rows_key`` down, ``cols_key`` across."""
    for rate in rates:
        pivot = summary.pivot_table(index=rows_key, columns=cols_key, values=f"{rate}_rate", sort=True)
        if cols_key == "planner":
            pivot = pivot[[p for p in PLANNERS if p in pivot.columns]]
        header = [
            f"{rate.replace('_', ' ')} rate: {AXIS_LABELS.get(rows_key, rows_key)} \\ "
            f"{AXIS_LABELS.get(cols_key, cols_key)}"
        ] + [_label(c) for c in pivot.columns]
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


def _timings(doc: Document, r: RunRecord) -> None:
    doc.heading(1, "Wall time")
    rows = []
    for name, res in r.results.items():
        n_cells = 1 if res.summary is None else len(res.summary)
        if res.table is not None:
            scenarios = len(res.table)
        elif res.summary is not None:
            scenarios = int(res.summary["samples"].sum())
        else:
            scenarios = res.trace["planner"].nunique()
        rows.append([name, n_cells, scenarios, _f(r.timings[name], ".2f")])
    rows += [[k, "", "", _f(v, ".2f")] for k, v in r.timings.items() if k not in r.results]
    rows.append(["**total**", "", "", f"**{sum(r.timings.values()):.2f}**"])
    doc.table(["step", "cells", "scenarios", "seconds"], rows)
