"""The paper-faithful and the safe mode side by side in the report (safelane.experiments.modes)."""

from __future__ import annotations

import pandas as pd

from ..experiments.modes import modes_side_by_side
from ..experiments.paper_data import PLANNERS
from . import prose
from .document import Document


def section(doc: Document, table1: pd.DataFrame, safe: pd.DataFrame) -> None:
    """Per published cell: paper-faithful / safe mode / paper, and the safe mode's MAE and collision count."""
    frame = modes_side_by_side(table1, safe)
    doc.paragraph(modes_paragraph(frame, table1, safe))
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


def _bad(summary: pd.DataFrame) -> tuple[int, int, int]:
    """``(collisions, p_m violations, scenarios)`` of a summary."""
    collisions = round((summary["collision_rate"] * summary["samples"]).sum())
    violations = round((summary["safety_violation_rate"] * summary["samples"]).sum())
    return int(collisions), int(violations), int(summary["samples"].sum())


def modes_paragraph(frame: pd.DataFrame, table1: pd.DataFrame, safe: pd.DataFrame) -> str:
    """The side-by-side's sentence, every word chosen by the numbers (``frame``: ``modes_side_by_side``)."""
    mae_pf = float((frame["paper_faithful"] - frame["paper_success"]).abs().mean())
    mae_safe = float((frame["safe_mode"] - frame["paper_success"]).abs().mean())
    keys = ["planner", "n_leaders", "decel"]
    same_cells = table1.merge(safe[keys].drop_duplicates(), on=keys)  # the paper-faithful run on the same cells
    c_safe, v_safe, n_safe = _bad(safe)
    c_pf, v_pf, n_pf = _bad(same_cells)
    guarantee = (
        "none, as its zero-violation guarantee requires" if c_safe == v_safe == 0
        else "its zero-violation guarantee does not hold in this run (see docs/reproduction.md on the assessment it "
        "assumes)"
    )  # fmt: skip
    return (
        f"Success per published cell, paper-faithful / safe mode / paper. Mean absolute difference to the paper: "
        f"paper-faithful **{mae_pf:.3f}**, safe mode **{mae_safe:.3f}** (the safe mode is "
        f"{prose.closer(mae_safe, mae_pf, 'the paper', 'the paper-faithful mode')}). Safe mode: "
        f"{prose.plural(c_safe, 'collision')} and {prose.plural(v_safe, '`p_m` violation')} in {n_safe} scenarios — "
        f"{guarantee}. Paper-faithful mode in the same cells: "
        f"{prose.plural(c_pf, 'collision')} and {prose.plural(v_pf, '`p_m` violation')} in {n_pf} scenarios (it "
        "carries no guarantee)."
    )


def nn_section(doc: Document, nn: pd.DataFrame, rules: pd.DataFrame) -> None:
    """The reported Table 1 (the preset's network) beside the rule-based planner it imitates."""
    from ..experiments.rules_table import nn_beside_rules

    frame = nn_beside_rules(nn, rules)
    published = frame.dropna(subset=["paper_success"])
    gap = frame["nn_minus_rules"].abs()
    mae_nn = float((published["nn"] - published["paper_success"]).abs().mean())
    mae_rules = float((published["rule_based"] - published["paper_success"]).abs().mean())
    doc.paragraph(
        f"Success per cell, NN / rule-based (/ paper where published). NN vs rule-based: mean absolute difference "
        f"**{gap.mean():.3f}**, largest **{gap.max():.3f}**; NN vs the paper's published cells: mean absolute "
        f"difference **{mae_nn:.3f}** (rule-based: {mae_rules:.3f}; the network is "
        f"{prose.closer(mae_nn, mae_rules, 'the paper', 'the planner it imitates')})."
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
