"""The report in a real browser (issue 31): headless Chromium lays out the page built from the committed run's data;
the screenshots are not blank, every table-of-contents link lands on an element that exists, no heading is an
internal id, the claims' statements are left-aligned, figures fit the page width. Skips, saying why, without
chromium (``apt-get install chromium``); benchmarks/report_screenshot.py does the same by hand."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from safelane.experiments.registry import EXPERIMENTS

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("report_screenshot", ROOT / "benchmarks" / "report_screenshot.py")
shots = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(shots)

pytestmark = pytest.mark.skipif(
    shots.find_chromium() is None, reason="chromium is not installed (Debian: apt-get install chromium)"
)


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Path:
    from safelane.reporting.report import build_document
    from test_report_layout import committed_record

    tmp = tmp_path_factory.mktemp("page")
    doc = build_document(committed_record(tmp, figures=("fig4_n5", "rss_baseline")))
    path = tmp / "report.html"
    path.write_text(doc.to_html(), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def laid_out(page) -> dict:
    return shots.probe(page, width=1280, height=900)


def test_screenshots_are_not_blank(page, tmp_path):
    first = shots.screenshot(page, tmp_path / "first.png", width=1280, height=900)
    section = shots.screenshot(page, tmp_path / "section.png", width=1280, height=900, anchor=shots.FIGURE_SECTION)
    assert not shots.blank(first) and not shots.blank(section)


def test_toc_links_resolve_in_the_browser(laid_out):
    assert len(laid_out["links"]) >= 10
    assert set(laid_out["links"]) <= set(laid_out["ids"]), set(laid_out["links"]) - set(laid_out["ids"])
    assert shots.FIGURE_SECTION in laid_out["ids"]


def test_no_heading_is_an_internal_id_in_the_browser(laid_out):
    texts = [text for _, text in laid_out["headings"]]
    bad = [t for t in texts if t in EXPERIMENTS or re.fullmatch(r"[a-z0-9]+(_[a-z0-9]+)+", t)]
    assert len(texts) >= 15 and not bad, bad


def test_prose_left_numbers_right_figures_fit(laid_out):
    assert laid_out["statements"] and set(laid_out["statements"]) == {"left"}  # was: right
    assert laid_out["numbers"] and set(laid_out["numbers"]) == {"right"}
    assert len(laid_out["figures"]) == 2
    for fig in laid_out["figures"]:
        assert 0 < fig["shown"] <= laid_out["content_width"] and not re.fullmatch(r"[a-z0-9_]+", fig["alt"])
    assert laid_out["smallest_font_px"] >= 12
