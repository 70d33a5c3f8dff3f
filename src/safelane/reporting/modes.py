"""The paper-faithful and the safe mode side by side in the report (issue 12; safelane.experiments.modes)."""

from __future__ import annotations

import pandas as pd

from ..experiments.modes import modes_side_by_side
from ..experiments.paper_data import PLANNERS
from .document import Document


def section(doc: Document, table1: pd.DataFrame, safe: pd.DataFrame) -> None:
    """Per published cell: paper-faithful / safe mode / paper, and the safe mode's MAE and collision count."""
    frame = modes_side_by_side(table1, safe)
    mae_pf = (frame["paper_faithful"] - frame["paper_success"]).abs().mean()
    mae_safe = (frame["safe_mode"] - frame["paper_success"]).abs().mean()
    bad = round((safe["collision_rate"] * safe["samples"]).sum() + (safe["safety_violation_rate"]
                                                                         * safe["samples"]).sum())  # fmt: skip
    doc.paragraph(
        f"Success per published cell, paper-faithful / safe mode / paper. Mean absolute difference to the paper: "
        f"paper-faithful **{mae_pf:.3f}**, safe mode **{mae_safe:.3f}**; safe mode: {bad} collisions or `p_m` "
        f"violations in {int(safe['samples'].sum())} scenarios (it carries the zero-violation guarantee; the "
        "paper-faithful mode does not, see docs/reproduction.md)."
    )
    cell = frame.set_index(["n_leaders", "decel", "planner"])
    rows = []
    for (n, d), _ in frame.groupby(["n_leaders", "decel"], sort=True):
        row = [n, f"{d:g}"]
        for p in PLANNERS:
            if (n, d, p) in cell.index:
                c = cell.loc[(n, d, p)]
                row.append(f"{c['paper_faithful']:.3f} / {c['safe_mode']:.3f} / {c['paper_success']:g}")
            else:
                row.append("—")
        rows.append(row)
    doc.table(["N", "a [m/s²]", *PLANNERS], rows)


def nn_section(doc: Document, nn: pd.DataFrame, rules: pd.DataFrame) -> None:
    """The reported Table 1 (the preset's network) beside the rule-based planner it imitates."""
    from ..experiments.rules_table import nn_beside_rules

    frame = nn_beside_rules(nn, rules)
    published = frame.dropna(subset=["paper_success"])
    gap = frame["nn_minus_rules"].abs()
    doc.paragraph(
        f"Success per cell, NN / rule-based (/ paper where published). NN vs rule-based: mean absolute difference "
        f"**{gap.mean():.3f}**, largest **{gap.max():.3f}**; NN vs the paper's published cells: mean absolute "
        f"difference **{(published['nn'] - published['paper_success']).abs().mean():.3f}** (rule-based: "
        f"{(published['rule_based'] - published['paper_success']).abs().mean():.3f})."
    )
    cell = frame.set_index(["n_leaders", "decel", "planner"])
    rows = []
    for (n, d), _ in frame.groupby(["n_leaders", "decel"], sort=True):
        row = [n, f"{d:g}"]
        for p in PLANNERS:
            if (n, d, p) not in cell.index:
                row.append("—")
                continue
            c = cell.loc[(n, d, p)]
            paper = "" if pd.isna(c["paper_success"]) else f" / {c['paper_success']:g}"
            row.append(f"{c['nn']:.3f} / {c['rule_based']:.3f}{paper}")
        rows.append(row)
    doc.table(["N", "a [m/s²]", *PLANNERS], rows)
