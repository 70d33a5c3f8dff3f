"""``reproduce``: every experiment runs, the report holds every claim and figure, the same seed gives the same
files; the report's document model; the ``reproduce`` and ``calibrate`` commands."""

from __future__ import annotations

import datetime as dt
import html
import subprocess
import sys

import pandas as pd
import pytest
from typer.testing import CliRunner

from safelane import Params
from safelane.cli import app
from safelane.experiments import calibration
from safelane.experiments import reproduce as reproduce_module
from safelane.experiments.calibration import Preset
from safelane.experiments.registry import EXPERIMENTS
from safelane.experiments.reproduce import reproduce, run_id
from safelane.reporting.document import Document, data_uri, inline_html
from safelane.reporting.figures import FIGURES
from safelane.reporting.report import PIVOTS
from safelane.sim.engine import SimConfig

CLAIM_KEYS = {
    "zero_collisions",
    "ordering",
    "follower_information",
    "chain_information",
    "conclusion_1",
    "falls_with_decel",
    "rises_with_n",
    "robust_low_pv",
    "degrades_high_pv",
    "fig5_cv_all_3s",
    "fig5_turn_back_3s",
    "fig5_follow_longer",
    "fig5_none_coincide",
}
META = {
    "loss_mean_abs_diff": 0.1234,
    "procedure": "test procedure",
    "search_space": {"a_x_a": [1.0, 3.0], "p_m": [5.0, 10.0]},
    "command": "safelane calibrate --candidates 2",
    "per_cell": [{"n_leaders": 1, "decel": 2.0, "planner": "CV_all", "paper_success": 1.0, "success_rate": 0.98}],
}
PRESET = Preset("test", Params(), SimConfig(horizon_s=4.0), META)  # a short horizon keeps the runs fast


def tiny_configs() -> dict:
    """Every experiment's quick grid with even fewer samples per cell."""
    return {
        name: exp.config_type(**{**exp.quick, "samples": 5})
        for name, exp in EXPERIMENTS.items()
        if "samples" in exp.config_type.model_fields
    }


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("results")
    kwargs = dict(seed=3, quick=True, preset=PRESET, progress=False, configs=tiny_configs())
    return reproduce(base, **kwargs), reproduce(base, **kwargs)


def test_every_experiment_runs_and_writes_tables_and_figures(runs):
    run = runs[0]
    for name in EXPERIMENTS:
        kinds = ("trace",) if EXPERIMENTS[name].cells is None else ("scenarios", "summary")
        for kind in kinds:
            frame = pd.read_csv(run / "data" / f"{name}_{kind}.csv")
            assert len(frame) > 0
        for suffix in (".png", ".svg"):
            assert (run / "figures" / f"{name}{suffix}").stat().st_size > 0
    assert (run / "data" / "table1_side_by_side.csv").exists()
    assert "fig5_example" in (run / "run.json").read_text()


def test_report_contains_every_claim(runs):
    run = runs[0]
    md, page = (run / "report.md").read_text(), (run / "report.html").read_text()
    claims = pd.read_csv(run / "data" / "claims.csv")
    assert set(claims["key"]) == CLAIM_KEYS
    for key, text in zip(claims["key"], claims["text"], strict=True):
        assert f"`{key}`" in md and text in md
        assert f"<code>{key}</code>" in page and html.escape(text) in page
    assert "**holds**" in md or "**does not hold**" in md


def test_report_contains_every_figure(runs):
    run = runs[0]
    md, page = (run / "report.md").read_text(), (run / "report.html").read_text()
    figures = sorted((run / "figures").glob("*.png"))
    assert {p.stem for p in figures} == set(EXPERIMENTS)
    for png in figures:
        assert f"](figures/{png.name})" in md
        assert f"figures/{png.stem}.svg" in md
        assert data_uri(png) in page
    assert 'src="figures/' not in page  # self-contained: images are embedded


def test_report_sections(runs):
    md = (runs[0] / "report.md").read_text()
    assert md.startswith("# Reproduction")
    assert "**Headline.**" in md and "mean absolute difference" in md
    assert "Our prediction for N = 3 (a prediction" in md
    assert "seed **3**" in md and "safelane reproduce --seed 3 --quick" in md
    assert "0.1234" in md and "safelane calibrate --candidates 2" in md  # calibration record
    for key in ("python", "numpy", "pandas", "safelane", "platform"):
        assert f"| {key} |" in md
    for name in EXPERIMENTS:
        assert f"| {name} |" in md  # wall time per experiment
    assert "pyarrow" in md


def test_same_seed_gives_identical_tables(runs):
    a, b = runs
    assert a != b  # two runs in the same second get two folders
    csvs = sorted(p.name for p in (a / "data").glob("*.csv"))
    assert csvs == sorted(p.name for p in (b / "data").glob("*.csv"))
    for name in csvs:
        assert (a / "data" / name).read_bytes() == (b / "data" / name).read_bytes(), name
    for svg in (a / "figures").glob("*.svg"):
        assert svg.read_bytes() == (b / "figures" / svg.name).read_bytes(), svg.name


def test_every_experiment_has_a_figure_and_report_views_are_registered():
    assert set(FIGURES) == set(EXPERIMENTS)
    assert set(PIVOTS) <= set(EXPERIMENTS)


def test_reproduce_rejects_configs_of_experiments_that_do_not_run(tmp_path):
    with pytest.raises(ValueError, match="do not run"):
        reproduce(tmp_path, preset=PRESET, progress=False, experiments=["fig5_example"], configs=tiny_configs())
    assert not any(tmp_path.iterdir())


def test_run_id():
    now = dt.datetime(2025, 1, 2, 3, 4, 5, tzinfo=dt.timezone.utc)
    assert run_id(7, True, now) == "20250102T030405Z-seed7-quick"
    assert run_id(0, False, now) == "20250102T030405Z-seed0-full"


# -- the document model ------------------------------------------------------------------------------------------
def test_inline_html_escapes_and_converts():
    assert inline_html("a < b & **c** `d<e>` [f](g.csv)") == (
        'a &lt; b &amp; <strong>c</strong> <code>d&lt;e&gt;</code> <a href="g.csv">f</a>'
    )


def test_markdown_and_html_render_the_same_blocks():
    doc = Document("T")
    doc.heading(1, "Section")
    doc.table(["x", "y|z"], [[1, "a|b"]])
    doc.bullets(["one"])
    md, page = doc.to_markdown(), doc.to_html()
    assert "## Section" in md and "| x | y\\|z |" in md and "| 1 | a\\|b |" in md and "- one" in md
    assert "<h2>Section</h2>" in page and "<td>a|b</td>" in page and "<li>one</li>" in page


# -- the commands ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["reproduce", "calibrate"])
def test_help(command):
    result = CliRunner().invoke(app, [command, "--help"])
    assert result.exit_code == 0 and "Example: safelane " + command in result.output


def test_reproduce_command_passes_its_options(monkeypatch, tmp_path):
    seen = {}

    def fake(out, **kwargs):
        seen.update(kwargs, out=out)
        return tmp_path / "run"

    monkeypatch.setattr(reproduce_module, "reproduce", fake)
    args = ["reproduce", "--quick", "--seed", "4", "--out", str(tmp_path), "--workers", "2", "--no-progress"]
    result = CliRunner().invoke(app, [*args, "--only", "table1"])
    assert result.exit_code == 0, result.output
    assert str(tmp_path / "run") in result.output
    assert seen["out"] == tmp_path and seen["seed"] == 4 and seen["quick"] and seen["workers"] == 2
    assert seen["experiments"] == ["table1"] and seen["preset"] == "paper" and not seen["progress"]


def test_reproduce_command_unknown_preset(tmp_path):
    result = CliRunner().invoke(app, ["reproduce", "--preset", "nope", "--out", str(tmp_path), "--no-progress"])
    assert result.exit_code == 2
    assert "not found" in result.output
    assert not any(tmp_path.iterdir())


def test_calibrate_command_writes_and_installs(monkeypatch, tmp_path):
    def fake(candidates, samples, refine, finalists, final_samples, seed, on_candidate, workers):
        point = {k: lo for k, (lo, _) in calibration.SEARCH_SPACE.items()}
        for i in range(candidates + refine + finalists):
            on_candidate(i, point, 0.5 - 0.01 * i)
        frame = pd.DataFrame([{**point, "loss": 0.5, "stage": 1}])
        return Preset("paper", Params(), SimConfig(), META), frame

    monkeypatch.setattr(calibration, "calibrate", fake)
    monkeypatch.setenv("SAFELANE_PRESET_DIR", str(tmp_path / "presets"))
    shipped = calibration.PRESET_DIR / "paper.yaml"
    before = shipped.read_bytes()
    out = tmp_path / "cal"
    result = CliRunner().invoke(
        app, ["calibrate", "--candidates", "2", "--refine", "1", "--out", str(out), "--install", "--name", "mine"]
    )
    assert result.exit_code == 0, result.output
    assert "0.4900" in result.output  # the candidates table
    assert "/5" in result.output and "left]" in result.output  # the total and the time left
    (run,) = out.iterdir()
    for name in ("preset.yaml", "candidates.csv", "fit_per_cell.csv", "run.json"):
        assert (run / name).exists()
    installed = calibration.load_preset("mine")  # a user preset, by name
    assert installed.meta["loss_mean_abs_diff"] == 0.1234 and installed.name == "mine"
    assert installed.source == str(tmp_path / "presets" / "mine.yaml")
    assert shipped.read_bytes() == before  # the package's own files are never written
    refused = CliRunner().invoke(app, ["calibrate", "--out", str(out), "--install", "--name", "paper"])
    assert refused.exit_code == 2 and "shipped preset" in refused.output


def test_importing_the_package_and_commands_does_not_import_plotting():
    code = (
        "import sys, safelane, safelane.experiments.reproduce, safelane.cli; "
        "print('matplotlib' in sys.modules, any(m.startswith('safelane.reporting') for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]
