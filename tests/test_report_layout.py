"""The report's layout (issue 31): a table of contents whose links resolve, human titles for every section and figure
(no internal id as a heading), prose cells left-aligned and numbers right-aligned, every figure legible at the
page width. Built from the committed run's data (docs/results/data), without simulating."""

from __future__ import annotations

import html
import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

from safelane.experiments.registry import EXPERIMENTS
from safelane.reporting.document import Document

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "docs" / "results"
PAGE_WIDTH_PX = 1100  # the report's max content width (CSS pixels)
PNG_DPI = 150  # the PNGs' resolution; the page shows them at their pixel size, scaled down to the page width
MIN_TEXT_PX = 12.0
INTERNAL_ID = re.compile(r"^[a-z0-9]+(_[a-z0-9]+)+$")  # fig4_n5, table1_rules…


def committed_run(tmp_path: Path, figures=()) -> Path:
    """A run folder from the committed data: its summaries and trace, a run.json with the default configs."""
    from safelane.experiments.reproduce import software_versions

    run = tmp_path / "run"
    (run / "data").mkdir(parents=True)
    for csv in (COMMITTED / "data").glob("*.csv"):
        shutil.copyfile(csv, run / "data" / csv.name)
    info = {
        "run_id": "committed", "started_utc": "2026-01-01 00:00:00", "seed": 0, "quick": False,
        "command": "safelane reproduce --workers 2", "preset": {"name": "paper"},
        "configs": {n: e.default_config().model_dump(mode="json") for n, e in EXPERIMENTS.items()},
        "versions": software_versions(), "parquet": False, "timings_s": {n: 1.0 for n in EXPERIMENTS},
    }  # fmt: skip
    (run / "run.json").write_text(json.dumps(info), encoding="utf-8")
    return run


def committed_record(tmp_path: Path, figures=("fig4_n5",)):
    """A RunRecord of the committed run's results (no simulation; ``figures`` drawn into ``tmp_path``)."""
    from safelane.experiments.calibration import load_preset
    from safelane.experiments.claims import check_claims, table1_side_by_side
    from safelane.experiments.runner import ExperimentResult
    from safelane.reporting.figures import FIGURES
    from safelane.reporting.report import RunRecord

    results = {}
    for name, exp in EXPERIMENTS.items():
        kind = "trace" if exp.cells is None else "summary"
        frame = pd.read_csv(COMMITTED / "data" / f"{name}_{kind}.csv")
        summary, trace = (None, frame) if kind == "trace" else (frame, None)
        table = None if summary is None else pd.DataFrame(index=range(int(summary["samples"].sum())))  # sized only
        results[name] = ExperimentResult(name, exp.default_config(), table, summary, trace, 1.0)
    summaries = {n: r.summary for n, r in results.items() if r.summary is not None and EXPERIMENTS[n].feeds_claims}
    side, mae = table1_side_by_side(summaries["table1"])
    drawn = {n: FIGURES[n](results[n].summary, tmp_path / "figures", 1.75) for n in figures}
    return RunRecord(
        run_id="committed", run_dir=tmp_path, seed=0, quick=False, command="safelane reproduce --workers 2",
        preset=load_preset("paper"), results=results,
        claims=check_claims(summaries, fig5_trace=results["fig5_example"].trace), side_by_side=side, mae=mae,
        figures=drawn, data_files=[], versions={"python": "3"}, parquet=False, timings={n: 1.0 for n in results},
        started_utc="2026-01-01 00:00:00",
    )  # fmt: skip


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """``(markdown, html)`` of the report built from the committed data (one figure drawn, to keep it fast)."""
    from safelane.reporting.report import build_document

    doc = build_document(committed_record(tmp_path_factory.mktemp("r")))
    return doc.to_markdown(), doc.to_html()


class _Page(HTMLParser):
    """Headings (level, text), ids, in-page links, and every table cell's (class, text)."""

    def __init__(self):
        super().__init__()
        self.headings, self.ids, self.links, self.cells, self._open = [], set(), [], [], None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if "id" in attrs:
            self.ids.add(attrs["id"])
        if tag == "a" and attrs.get("href", "").startswith("#"):
            self.links.append(attrs["href"][1:])
        if re.fullmatch(r"h[1-6]", tag) or tag == "td":
            self._open = [tag, attrs.get("class", ""), ""]

    def handle_data(self, data):
        if self._open is not None:
            self._open[2] += data

    def handle_endtag(self, tag):
        if self._open is not None and tag == self._open[0]:
            kind, cls, text = self._open
            (self.cells.append((cls, text)) if kind == "td" else self.headings.append((int(kind[1]), text.strip())))
            self._open = None


def parse(page: str) -> _Page:
    p = _Page()
    p.feed(page)
    return p


def test_toc_links_resolve_to_headings(report):
    md, page = report
    p = parse(page)
    assert len(p.links) >= 10 and set(p.links) <= p.ids, set(p.links) - p.ids
    # every section of level 1 and 2 is in the ToC, in the order of the page
    sections = [h for lvl, h in p.headings if lvl in (2, 3)]
    toc = re.search(r'<nav class="toc".*?</nav>', page, re.S).group(0)
    assert [html.unescape(t) for t in re.findall(r'<a href="#[^"]+">(.*?)</a>', toc)] == sections
    assert "**Contents**" in md and "- [The paper's claims](#the-papers-claims)" in md


def test_no_heading_is_an_internal_id(report):
    md, page = report
    headings = [t for _, t in parse(page).headings]
    assert len(headings) >= 15
    bad = [h for h in headings if INTERNAL_ID.match(h) or h in EXPERIMENTS]
    assert not bad, bad
    for line in md.splitlines():
        if line.startswith("#"):
            text = line.lstrip("#").strip()
            assert not INTERNAL_ID.match(text) and text not in EXPERIMENTS, line
    # every experiment has a section of its own, with its figure's title, and names its id in the text once
    from safelane.reporting.report import title

    for name in EXPERIMENTS:
        assert f"## {title(name)}" in md.replace("### ", "## ")
        assert f"Experiment `{name}`" in md


def test_figures_have_human_alt_text(report):
    _, page = report
    alts = re.findall(r'<img src="data:[^"]+" alt="([^"]*)"', page)
    assert alts and all(not INTERNAL_ID.match(a) for a in alts)


def test_prose_cells_left_aligned_and_number_cells_right_aligned(report):
    _, page = report
    cells = parse(page).cells
    css = re.search(r"<style>(.*?)</style>", page, re.S).group(1)
    base = re.search(r"(^|\n)\s*th, td \{([^}]*)\}", css).group(2)
    assert "text-align: left" in base  # was: right, for every cell (the claims' statements included)
    assert re.search(r"td\.num \{[^}]*text-align: right", css)
    statements = [text for cls, text in cells if text.startswith("Ordering CV_all >= CV_follow")]
    assert statements and all(cls != "num" for cls, text in cells if text in statements)
    numbers = [cls for cls, text in cells if re.fullmatch(r"[+-]?\d+\.\d{3}", text)]
    assert numbers and all(cls == "num" for cls in numbers)


def test_document_toc_in_markdown_and_html_agree():
    doc = Document("T")
    doc.contents()
    doc.heading(1, "Fig. 4: success vs `a`")
    doc.heading(2, "Sub")
    doc.heading(1, "Fig. 4: success vs `a`")  # a repeated title gets a unique anchor, as on GitHub
    md, page = doc.to_markdown(), doc.to_html()
    toc = "- [Fig. 4: success vs a](#fig-4-success-vs-a)\n  - [Sub](#sub)\n"
    toc += "- [Fig. 4: success vs a](#fig-4-success-vs-a-1)"
    assert toc in md
    p = parse(page)
    assert p.links == ["fig-4-success-vs-a", "sub", "fig-4-success-vs-a-1"] and set(p.links) <= p.ids


def _figures_drawn(monkeypatch, tmp_path) -> dict:
    """Draw every registered figure from the committed data (not saved: fonts are set when drawn); returns
    stem -> the matplotlib figure."""
    import safelane.reporting.figures as figures
    import safelane.reporting.rss as rss

    drawn = {}

    def keep(fig, out_dir, stem):
        drawn[stem] = fig
        return []

    monkeypatch.setattr(figures, "_save", keep)
    monkeypatch.setattr(rss, "_save", keep)
    for name, draw in figures.FIGURES.items():
        kind = "trace" if EXPERIMENTS[name].cells is None else "summary"
        draw(pd.read_csv(COMMITTED / "data" / f"{name}_{kind}.csv"), tmp_path, 1.75)
    return drawn


def test_every_figure_is_legible_at_the_page_width(monkeypatch, tmp_path):
    from matplotlib.text import Text

    drawn = _figures_drawn(monkeypatch, tmp_path)
    assert set(drawn) == set(EXPERIMENTS)
    small = {}
    for stem, fig in drawn.items():
        scale = min(1.0, PAGE_WIDTH_PX / (fig.get_figwidth() * PNG_DPI))  # the page shrinks wide PNGs to fit
        for t in fig.findobj(Text):
            if t.get_visible() and t.get_text().strip():
                px = t.get_fontsize() * PNG_DPI / 72 * scale
                if px < MIN_TEXT_PX:
                    small.setdefault(stem, []).append((t.get_text(), round(px, 1)))
    assert not small, small  # was: rss_baseline's labels 7.8 px, table1's legend 8.5 px


def test_rebuild_from_a_run_folder_marks_files_it_does_not_hold(tmp_path):
    """``safelane.reporting.rebuild`` (how docs/results is published): the report of a folder without the
    per-scenario CSVs links what it holds and says how to get the rest."""
    from safelane.reporting.rebuild import record_from_folder
    from safelane.reporting.report import build_document

    run = committed_run(tmp_path)
    record = record_from_folder(run, figures=False)
    assert record.seed == 0 and set(record.results) == set(EXPERIMENTS) and record.figures == {}
    md = build_document(record).to_markdown()
    assert "- [data/table1_summary.csv](data/table1_summary.csv)" in md
    assert "- data/table1_scenarios.csv — not committed (per-scenario, large): `safelane reproduce --seed 0`" in md
    claims = pd.read_csv(COMMITTED / "data" / "claims.csv")
    assert [c.key for c in record.claims] == list(claims["key"])  # recomputed from the CSVs: the committed verdicts
    assert [c.holds for c in record.claims] == [None if pd.isna(h) else bool(h) for h in claims["holds"]]
