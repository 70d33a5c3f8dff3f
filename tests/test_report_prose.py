"""The report's sentences are computed from the tables they describe (issue 31): each test builds a table, renders the
prose, changes the table (flips which is larger, adds violations) and sees the sentence change with it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from safelane import Params
from safelane.experiments.calibration import Preset
from safelane.experiments.claims import Claim, table1_side_by_side
from safelane.reporting.document import Document
from safelane.reporting.modes import nn_section
from safelane.reporting.modes import section as modes_section
from safelane.reporting.report import RunRecord, build_document
from safelane.reporting.rss import paragraph
from safelane.sim.engine import SimConfig
from safelane.sim.metrics import wilson_interval

N = 4500
RSS = ("RSS", "RSS_V2X", "RSS_matched", "RSS_V2X_matched")
PAPER = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")


def rss_view(overrides: dict | None = None, followers=("collaborative", "aggressive", "ignores_ego")) -> pd.DataFrame:
    """An ``overview`` frame: every rate 0 except success 0.5, then ``overrides[(follower, planner)][rate]``."""
    rows = []
    for f in followers:
        for p in PAPER + RSS:
            rates = {"success": 0.5, "collision": 0.0, "safety_violation": 0.0, "collision_with_follower": 0.0,
                     "collision_with_leader": 0.0, **(overrides or {}).get((f, p), {})}  # fmt: skip
            row = {"follower": f, "planner": p, "samples": N}
            for c in ("success", "collision", "safety_violation"):
                k = round(rates[c] * N)
                lo, hi = wilson_interval(np.array([k]), np.array([N]))
                row |= {f"{c}_rate": k / N, f"{c}_lo": float(lo[0]), f"{c}_hi": float(hi[0])}
            for c in ("collision_with_follower", "collision_with_leader"):
                row[f"{c}_rate"] = rates[c]
            rows.append(row)
    return pd.DataFrame(rows)


def _issue_31_case(cv_all_success: float, cv_all_violation: float) -> str:
    """The committed run's collaborative numbers: CV_all 0.742 with 0.006 p_m violations, RSS_V2X_matched 0.771."""
    return paragraph(
        rss_view(
            {
                ("collaborative", "CV_all"): {"success": cv_all_success, "safety_violation": cv_all_violation},
                ("collaborative", "RSS_V2X_matched"): {"success": 0.771, "safety_violation": 0.655},
                ("collaborative", "RSS_matched"): {"success": 0.712, "safety_violation": 0.648},
            }
        )
    )


def test_rss_paragraph_says_fewer_and_with_violations_when_the_table_does():
    text = _issue_31_case(0.742, 0.006)
    # The sentence of issue 31 ("completes -2.9 percentage points more … without a p_m violation") is gone:
    assert "-2.9" not in text and "without a p_m violation" not in text
    assert "CV_all completes 2.9 percentage points fewer lane changes than the best RSS variant" in text
    assert "with p_m violations in 0.6 %" in text
    assert not re.search(r"[-+]\d[\d.]* percentage points (more|fewer)", text)  # never a sign against its word


def test_rss_paragraph_changes_when_the_table_flips():
    text = _issue_31_case(0.900, 0.0)  # CV_all now clearly above, no violation
    assert "CV_all completes 12.9 percentage points more lane changes than the best RSS variant" in text
    assert "without a p_m violation" in text
    assert "fewer lane changes than the best RSS variant" not in text
    same = _issue_31_case(0.770, 0.0)  # inside the 95 % intervals of 0.771
    assert "as many lane changes (within sampling noise) as the best RSS variant" in same


def test_rss_paragraph_v2x_effect_sign_follows_the_table():
    gain = _issue_31_case(0.742, 0.006)
    assert "V2X (L1's promised bound as its brake_max) adds 5.9 percentage points of success" in gain
    loss = paragraph(rss_view({("collaborative", "RSS_matched"): {"success": 0.8},
                               ("collaborative", "RSS_V2X_matched"): {"success": 0.7}}))  # fmt: skip
    assert "costs 10.0 percentage points of success" in loss and "adds" not in loss


def test_rss_paragraph_never_rounds_a_collision_to_zero():
    one = paragraph(rss_view({("collaborative", "CV_all"): {"collision": 1 / N}}))
    assert f"with 0.022 % (1 of {N}) collisions" in one  # was "with 0.0% collisions"
    none = paragraph(rss_view())
    assert "CV_all completes 50.0 % of the lane changes without a collision" in none


def test_rss_paragraph_collides_more_only_where_it_does():
    more = paragraph(rss_view({("ignores_ego", "CV_all"): {"collision": 0.7}}))
    assert "CV_all collides more often than any RSS variant (70.0 % against at most 0 %)" in more
    less = paragraph(rss_view({("ignores_ego", "CV_all"): {"collision": 0.1},
                               ("ignores_ego", "RSS"): {"collision": 0.5}}))  # fmt: skip
    assert "collides more" not in less and "CV_all collides less often than every RSS variant" in less


def test_rss_paragraph_limits_are_computed():
    none = paragraph(rss_view())  # RSS_matched without any p_m violation: no sentence explaining violations
    assert "With this world's limits (RSS_matched) it completes up to 50.0 %, without a p_m violation." in none
    assert "straddle" not in none
    assert "against initial gaps of 17–22 m" in none  # ScenarioConfig's gap, not a literal
    some = paragraph(rss_view({("aggressive", "RSS_matched"): {"safety_violation": 1.0}}))
    assert "with p_m violations in up to 100.0 % of its lane changes: its lateral safe distance" in some


# -- paper-faithful vs safe mode, NN vs rules --------------------------------------------------------------------
def summary(rate: float, *, collision: float = 0.0, violation: float = 0.0, samples: int = 300,
            n_leaders=(1, 10)) -> pd.DataFrame:  # fmt: skip
    rows = [{"planner": p, "n_leaders": n, "decel": d, "p_v": 0.0, "samples": samples, "success_rate": rate,
             "collision_rate": collision, "safety_violation_rate": violation}
            for n in n_leaders for d in (2.0, 3.0, 4.0, 5.0, 6.0) for p in PAPER]  # fmt: skip
    return pd.DataFrame(rows)


def _paragraphs(doc: Document) -> str:
    return " ".join(b[1] for b in doc.blocks if b[0] == "paragraph")


def test_modes_paragraph_follows_the_counts():
    doc = Document("t")
    modes_section(doc, summary(0.9, samples=1000), summary(0.5))
    clean = _paragraphs(doc)
    assert "0 collisions and 0 `p_m` violations in 12000 scenarios — none" in clean
    assert "the safe mode is further from the paper than the paper-faithful mode" in clean
    doc = Document("t")
    modes_section(doc, summary(0.9, samples=1000), summary(0.5, collision=1 / 300, violation=2 / 300))
    broken = _paragraphs(doc)
    assert "40 collisions and 80 `p_m` violations in 12000 scenarios" in broken
    assert "does not hold in this run" in broken and "carries the zero-violation guarantee" not in broken
    doc = Document("t")
    modes_section(doc, summary(0.5, samples=1000), summary(0.9))  # the other way round
    assert "the safe mode is closer to the paper than the paper-faithful mode" in _paragraphs(doc)


def test_nn_paragraph_comparison_follows_the_numbers():
    from safelane.experiments.paper_data import table1_long

    paper = pd.DataFrame(table1_long()).rename(columns={"paper_success": "rate"})
    nn = paper.assign(p_v=0.0, samples=1000, success_rate=paper["rate"]).drop(columns="rate")
    off = nn.assign(success_rate=(nn["success_rate"] - 0.1).clip(0, 1))
    doc = Document("t")
    nn_section(doc, nn, off)  # the network on the paper's numbers, the rules 0.1 below
    assert "the network is closer to the paper than the planner it imitates" in _paragraphs(doc)
    doc = Document("t")
    nn_section(doc, off, nn)
    assert "the network is further from the paper than the planner it imitates" in _paragraphs(doc)


# -- Table 1 and the claims, through the whole document ----------------------------------------------------------
def _record(tmp_path: Path, side: pd.DataFrame, mae: float, claims: list[Claim]) -> RunRecord:
    preset = Preset("test", Params(), SimConfig(), {})
    return RunRecord(
        run_id="r", run_dir=tmp_path, seed=0, quick=True, command="safelane reproduce", preset=preset, results={},
        claims=claims, side_by_side=side, mae=mae, figures={}, data_files=[], versions={}, parquet=False,
        timings={}, started_utc="2026-01-01 00:00:00",
    )  # fmt: skip


@pytest.mark.parametrize("delta, side", [(0.2, "above"), (-0.2, "below")])
def test_table1_sentence_names_the_largest_difference_and_its_side(tmp_path, delta, side):
    paper = pd.DataFrame(table1_long_frame())
    ours = paper.assign(success_rate=paper["paper_success"], p_v=0.0, samples=1000)
    cell = (ours["n_leaders"] == 1) & (ours["decel"] == 4.0) & (ours["planner"] == "CV_none")
    ours.loc[cell, "success_rate"] += delta
    frame, mae = table1_side_by_side(ours.assign(success_lo=0.0, success_hi=1.0).drop(columns="paper_success"))
    md = build_document(_record(tmp_path, frame, mae, [])).to_markdown()
    assert f"The largest difference is 0.200 (CV_none, N = 1, a = 4 m/s², ours {side} the paper's)" in md
    above, below = (1, 0) if delta > 0 else (0, 1)
    assert f"ours is above the paper in {above} cell{'s' if above != 1 else ''}, below in {below} and equal in 39" in md


def table1_long_frame():
    from safelane.experiments.paper_data import table1_long

    return table1_long()


def test_claims_sentence_counts_the_verdicts(tmp_path):
    claims = [Claim("a", "A.", True, "e"), Claim("b", "B.", False, "e"), Claim("c", "C.", None, "e")]
    md = build_document(_record(tmp_path, None, None, claims)).to_markdown()
    assert "1 of 2 checked claims hold, 1 does not; 1 could not be checked with the experiments that ran." in md
    claims[1] = Claim("b", "B.", True, "e")
    md = build_document(_record(tmp_path, None, None, claims)).to_markdown()
    assert "2 of 2 checked claims hold; 1 could not be checked" in md


def test_figure_captions_state_the_grid_of_the_results(tmp_path):
    """A caption's numbers (N, braking values, planners, samples) are read from the results, not a description."""
    from safelane.experiments.registry import EXPERIMENTS
    from safelane.experiments.runner import ExperimentResult

    def caption(n_leaders: int, decels: tuple[float, ...]) -> str:
        frame = summary(0.5, samples=40, n_leaders=(n_leaders,))
        frame = frame[frame["decel"].isin(decels)]
        table = pd.DataFrame(index=range(int(frame["samples"].sum())))  # sized only
        res = ExperimentResult("fig4_n5", EXPERIMENTS["fig4_n5"].default_config(), table, frame, None, 0.0)
        record = _record(tmp_path, None, None, [])
        record.results = {"fig4_n5": res}
        record.timings = {"fig4_n5": 0.0}
        return build_document(record).to_markdown()

    md = caption(7, (2.0, 6.0))
    assert "Grid: N = 7; a_x,N+1,d ∈ {2, 6} m/s²; 4 planners" in md and "40 scenarios per cell, 8 cells" in md
    assert "N = 5" not in md  # the registry's description says N = 5; these results do not
    assert "Grid: N = 3; a_x,N+1,d ∈ {2, 3, 4} m/s²" in caption(3, (2.0, 3.0, 4.0))
