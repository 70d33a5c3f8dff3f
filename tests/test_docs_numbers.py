"""Numbers the docs state come from one recorded source, so prose cannot drift from data.

* README's Table 1 (ours / the paper's), its headline numbers (MAE, worst cell, claims, collisions, the safe mode,
  the rule-based planner) against the committed run's CSVs in docs/results/data;
* docs/rss.md's comparison table against docs/results/data/rss_baseline_summary.csv;
* README's Python example computes the very cell the README's Table 1 reports (same preset, its own network);
* every wall time and scenario count stated for a command (README, docs/usage.md, docs/reproduction.md) against
  docs/results/timings.json, the recorded measurements (date, machine, load), and that file's scenario counts
  against the committed report's wall-time table.
"""

from __future__ import annotations

import itertools
import json
import re

import numpy as np
import pandas as pd
import pytest

from docs_blocks import REPO, fenced_blocks

DATA = REPO / "docs" / "results" / "data"
README = (REPO / "README.md").read_text(encoding="utf-8")
VARIANTS = ["CV_all", "CV_follow", "CV_none", "No_agg_assess"]


def _num(text: str) -> float:
    return float(text.replace(",", "").replace("−", "-"))


def _shown_equals(shown: str, value: float) -> bool:
    """``shown`` is ``value`` at the precision it is written with (``1`` is exactly 1; ``0.930`` to 3 decimals)."""
    decimals = len(shown.split(".")[1]) if "." in shown else 0
    return abs(_num(shown) - value) <= 0.5 * 10.0 ** -decimals + 1e-9


def _markdown_table(text: str, header_start: str) -> list[list[str]]:
    lines = text.split("\n")
    start = next(i for i, line in enumerate(lines) if line.startswith(header_start))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows


# ---------------------------------------------------------------- Table 1 and the headline numbers (README)

def _table1() -> tuple[pd.DataFrame, pd.DataFrame]:
    ours = pd.read_csv(DATA / "table1_summary.csv").set_index(["planner", "n_leaders", "decel"])
    side = pd.read_csv(DATA / "table1_side_by_side.csv").set_index(["planner", "n_leaders", "decel"])
    return ours, side


def _readme_table1_cells() -> list[tuple[str, int, float, str, str | None]]:
    """(variant, N, a, ours as shown, paper as shown or None) for every cell of README's Table 1."""
    cells = []
    for row in _markdown_table(README, "| N | a [m/s²] | CV_all | CV_follow"):
        n = int(row[0])
        lo, _, hi = row[1].partition("–")
        decels = [float(a) for a in range(int(lo), int(hi or lo) + 1)]
        for variant, cell in zip(VARIANTS, row[2:], strict=True):
            ours, _, paper = (part.strip() for part in cell.partition("/"))
            ours_list = [v.strip() for v in ours.split(",")]
            paper_list = [v.strip() for v in paper.split(",")] if paper else [None]
            for k, a in enumerate(decels):
                o = ours_list[k] if len(ours_list) > 1 else ours_list[0]
                p = paper_list[k] if len(paper_list) > 1 else paper_list[0]
                cells.append((variant, n, a, o, p))
    return cells


def test_readme_table1_matches_the_committed_run():
    ours, side = _table1()
    cells = _readme_table1_cells()
    assert len(cells) == 4 * 15, f"README's Table 1 should cover 4 variants x 15 (N, a) cells; got {len(cells)}"
    wrong = []
    for variant, n, a, o, p in cells:
        got = ours.loc[(variant, n, a), "success_rate"]
        if not _shown_equals(o, got):
            wrong.append(f"{variant} N={n} a={a:g}: README ours {o}, data {got:.3f}")
        paper = side.loc[(variant, n, a), "paper_success"] if (variant, n, a) in side.index else np.nan
        if p is None:
            if not np.isnan(paper):
                wrong.append(f"{variant} N={n} a={a:g}: the paper's {paper} not shown")
        elif np.isnan(paper) or not _shown_equals(p, paper):
            wrong.append(f"{variant} N={n} a={a:g}: README paper {p}, data {paper}")
    assert not wrong, "\n".join(wrong)


def _readme_number(pattern: str) -> str:
    m = re.search(pattern, README, flags=re.S)
    assert m, f"README no longer states {pattern!r}: update this test with the prose"
    return m.group(1)


def test_readme_headline_numbers_match_the_committed_run():
    ours, side = _table1()
    pub = side.dropna(subset=["paper_success"])
    diff = (pub["success_rate"] - pub["paper_success"]).abs()
    assert len(pub) == int(_readme_number(r"the paper's (\d+) published cells"))
    assert _shown_equals(_readme_number(r"mean absolute difference\s+\*\*([\d.]+)\*\*"), diff.mean())
    worst = diff.idxmax()
    assert _shown_equals(_readme_number(r"worst cell \*\*([\d.]+)\*\*"), diff.max())
    assert _readme_number(r"worst cell \*\*[\d.]+\*\* \(([^)]*)\)") == f"N = {worst[1]}, a = {worst[2]:g}, {worst[0]}"

    table = {(v, n, a): row for (v, n, a), row in pub.iterrows()}
    cells = sorted({(n, a) for _, n, a in table})

    def effect(col, hi, lo):
        return sum(table[(hi, n, a)][col] - table[(lo, n, a)][col] for n, a in cells)

    adj = np.mean([abs((table[(hi, n, a)]["success_rate"] - table[(lo, n, a)]["success_rate"])
                       - (table[(hi, n, a)]["paper_success"] - table[(lo, n, a)]["paper_success"]))
                   for hi, lo in itertools.pairwise(VARIANTS) for n, a in cells])
    assert _shown_equals(_readme_number(r"adjacent-variant differences \*\*([\d.]+)\*\*"), adj)
    follower, chain = effect("success_rate", "CV_follow", "CV_none"), effect("success_rate", "CV_all", "CV_follow")
    p_follower = effect("paper_success", "CV_follow", "CV_none")
    p_chain = effect("paper_success", "CV_all", "CV_follow")
    m = re.search(r"— ([\d.]+) vs ([\d.]+) summed over the published cells \(paper ([\d.]+) vs ([\d.]+)\)", README)
    assert m, "README's follower/chain effects sentence changed: update this test"
    for shown, value in zip(m.groups(), (follower, chain, p_follower, p_chain), strict=True):
        assert _shown_equals(shown, value), (shown, value)
    assert _shown_equals(_readme_number(r"\*\*([\d.]+)×, not the"), follower / chain)

    claims = pd.read_csv(DATA / "claims.csv")
    held, total = re.search(r"\*\*Claims\*\*: (\d+) of (\d+) hold", README).groups()
    assert (int(held), int(total)) == (int(claims["holds"].sum()), len(claims))
    evidence = claims.set_index("key").loc["zero_collisions", "evidence"]
    n_coll, n_viol, n_scen = re.match(r"(\d+) collisions and (\d+) safety-distance violations in (\d+) scenarios",
                                      evidence).groups()
    m = re.search(r"has \*\*(\d+) collisions\*\*.*?and (\d+) `p_m` violations in ([\d,]+) scenarios", README, re.S)
    assert m and (_num(m.group(1)), _num(m.group(2)), _num(m.group(3))) == (int(n_coll), int(n_viol), int(n_scen))
    largest = re.search(r"largest difference \+([\d.]+)", claims.set_index("key").loc["chain_information",
                                                                                          "evidence"]).group(1)
    assert _shown_equals(_readme_number(r"\(up to \+([\d.]+) at N = 5\)"), float(largest))

    rules = pd.read_csv(DATA / "table1_rules_summary.csv").set_index(["planner", "n_leaders", "decel"])
    gap = (rules["success_rate"] - ours["success_rate"]).abs().max()
    assert _shown_equals(_readme_number(r"within ([\d.]+) of the network's in every cell"), gap)

    safe = pd.read_csv(DATA / "table1_safe_mode_summary.csv").set_index(["planner", "n_leaders", "decel"])
    safe_pub = safe.join(pub["paper_success"], how="inner")
    assert _shown_equals(_readme_number(r"on the same cells: MAE ([\d.]+)"),
                         (safe_pub["success_rate"] - safe_pub["paper_success"]).abs().mean())
    assert "no collision, no violation" in README
    assert safe["collision_rate"].max() == 0 and safe["safety_violation_rate"].max() == 0
    samples = int(_readme_number(r"NN planner, (\d+) scenarios per cell"))
    assert (ours["samples"] == samples).all()


@pytest.mark.parametrize("block_line", [b.line for b in fenced_blocks(REPO / "README.md") if b.lang == "python"])
def test_readme_python_example_computes_the_reported_cell(block_line):
    """The README's `paper = simulate(...)` line, run as written, gives README's Table 1 cell (N = 1, a = 4,
    CV_all): the preset's own network, not the default world's."""
    block = next(b for b in fenced_blocks(REPO / "README.md") if b.line == block_line)
    line = next((ln for ln in block.text.splitlines() if ln.startswith("paper = simulate(")), None)
    if line is None:
        pytest.skip("this Python block has no `paper = simulate(...)` example")
    from safelane.sim import simulate

    paper = eval(line.split("=", 1)[1].split("#")[0].strip(), {"simulate": simulate})
    ours, _ = _table1()
    got = paper.summary()["success_rate"].iloc[0]
    m = re.search(r'simulate\("(\w+)", n_leaders=(\d+), decel=([\d.]+)', line)
    assert m, line
    variant, n, a = m.group(1), int(m.group(2)), float(m.group(3))
    expected = ours.loc[(variant, n, a), "success_rate"]
    assert got == pytest.approx(expected, abs=1e-12), f"README's example gives {got}, its Table 1 {expected}"
    shown = re.search(r"# ([\d.]+): Table 1's cell", block.text)
    assert shown and _shown_equals(shown.group(1), expected)


# ---------------------------------------------------------------- docs/rss.md's comparison table

def test_rss_comparison_table_matches_the_committed_run():
    text = (REPO / "docs" / "rss.md").read_text(encoding="utf-8")
    d = pd.read_csv(DATA / "rss_baseline_summary.csv")
    cols = ["success_rate", "collision_rate", "safety_violation_rate", "collision_with_follower_rate",
            "collision_with_leader_rate"]
    pooled = {}
    for (f, planner), g in d.groupby(["follower", "planner"]):
        pooled[(f, planner)] = [(g[c] * g["samples"]).sum() / g["samples"].sum() for c in cols]
    rows = _markdown_table(text, "| F | planner | success | collision |")  # the first such table: today's
    seen, wrong = set(), []
    for row in rows:
        for planner in re.split(r" / |, ", row[1]):
            key = (row[0], planner)
            seen.add(key)
            if key not in pooled:
                wrong.append(f"{key}: no such rows in the data")
                continue
            wrong += [f"{key} {c}: docs {s}, data {v:.4f}" for c, s, v in zip(cols, row[2:], pooled[key], strict=True)
                      if not _shown_equals(s, v)]
    assert not wrong, "\n".join(wrong)
    assert seen == set(pooled), f"rows missing from docs/rss.md's table: {sorted(set(pooled) - seen)}"


# ---------------------------------------------------------------- wall times and scenario counts of commands

TIMINGS = json.loads((REPO / "docs" / "results" / "timings.json").read_text(encoding="utf-8"))["measurements"]
USAGE = (REPO / "docs" / "usage.md").read_text(encoding="utf-8")


def test_timing_table_is_the_recorded_measurements():
    """docs/usage.md's table: one row per recorded measurement, every cell as recorded."""
    seen = []
    for row in _markdown_table(USAGE, "| command | scenarios | wall time | measured |"):
        command = re.search(r"`([^`]+)`", row[0]).group(1)
        wall = re.fullmatch(r"([\d.]+) s", row[2])
        assert wall, f"wall time {row[2]!r}: write it in seconds"
        match = [m for m in TIMINGS if m["command"] == command and _shown_equals(wall.group(1), m["wall_s"])]
        assert len(match) == 1, f"{command} {row[2]}: not a recorded measurement in docs/results/timings.json"
        m = match[0]
        assert (_num(row[1]) if row[1] else None) == m.get("scenarios"), (command, row[1], m.get("scenarios"))
        assert m["date"] in row[3], (command, row[3], m["date"])
        cpu = re.search(r"([\d.]+) CPU-seconds", row[3])
        assert (cpu is None) == ("cpu_s" not in m), f"{command}: state the recorded CPU time with the wall time"
        assert cpu is None or _shown_equals(cpu.group(1), m["cpu_s"])
        seen.append(m["id"])
    assert sorted(seen) == sorted(m["id"] for m in TIMINGS), "a recorded measurement is missing from the table"


def _report_wall_time() -> tuple[str, int, float]:
    report = (REPO / "docs" / "results" / "report.md").read_text(encoding="utf-8")
    run_id = re.search(r"Run `([^`]+)`", report).group(1)
    rows = _markdown_table(report, "| step | cells | scenarios | seconds |")
    scenarios = sum(int(r[2]) for r in rows if r[2])
    total = next(float(r[3].strip("*")) for r in rows if "total" in r[0])
    return run_id, scenarios, total


def test_recorded_reproduction_matches_the_committed_report():
    """The full grid's scenario count is the committed report's, and the committed run's wall time is recorded."""
    run_id, scenarios, total = _report_wall_time()
    full = [m for m in TIMINGS if m["command"] == "safelane reproduce --workers 2"]
    assert full and all(m["scenarios"] == scenarios for m in full), (scenarios, full)
    committed = [m for m in full if run_id in m["source"]]
    assert committed, (f"docs/results/report.md is now run {run_id}: record its wall time (the report's wall-time "
                       "table) in docs/results/timings.json and the docs' table")
    assert committed[0]["wall_s"] == pytest.approx(total, abs=0.05)


_COMMAND = re.compile(r"make run|reproduce|calibrate|safelane train|`train`|simulate`? with")
_DURATION = re.compile(r"(\d[\d,]*(?:\.\d+)?) ?(s|seconds|min|minutes)\b")
_COUNT = re.compile(r"(\d[\d,]*) (?:scenarios|lane changes)")


def _prose_sentences(text: str) -> list[str]:
    """Sentences outside fenced blocks and tables."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    text = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("|"))
    return [s.replace("\n", " ") for s in re.split(r"(?<=\.)\s+", text)]


def _stated_timings() -> list[tuple[str, str]]:
    reproduction = (REPO / "docs" / "reproduction.md").read_text(encoding="utf-8")
    runtime = reproduction.split("## Runtime", 1)[1].split("History", 1)[0]
    return [(where, s) for where, text in (("README.md", README), ("docs/usage.md", USAGE),
                                          ("docs/reproduction.md ## Runtime", runtime))
            for s in _prose_sentences(text) if _COMMAND.search(s)]


def test_every_stated_command_time_and_count_is_recorded():
    """A wall time or a scenario count stated beside a command in the prose is a recorded one."""
    walls = [m["wall_s"] for m in TIMINGS] + [m["cpu_s"] for m in TIMINGS if "cpu_s" in m]
    counts = {m["scenarios"] for m in TIMINGS if "scenarios" in m}
    wrong, checked = [], 0
    for where, sentence in _stated_timings():
        for value, unit in _DURATION.findall(sentence):
            seconds = _num(value) * (60 if unit.startswith("min") else 1)
            checked += 1
            if not any(abs(seconds - w) <= (0.05 if "." in value else 0.5) * (60 if unit.startswith("min") else 1)
                       for w in walls):
                wrong.append(f"{where}: {value} {unit} is not a recorded wall time: {sentence[:160]}")
        for value in _COUNT.findall(sentence):
            checked += 1
            if _num(value) not in counts:
                wrong.append(f"{where}: {value} scenarios is not a recorded count: {sentence[:160]}")
    assert not wrong, "\n".join(wrong)
    assert checked >= 3, "the README and docs/usage.md should state the reproduction's time and scenario count"
