"""``safelane simulate``: summary on screen, CSVs and a trace plot in a run folder, clear errors."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from safelane.cli import app

runner = CliRunner()
TINY = ["simulate", "--planner", "CV_none", "--leaders", "1", "--decel", "4", "--samples", "6", "--seed", "3"]
STEM = "CV_none_N1_decel4_pv0_seed3"


def _invoke(*args):
    return runner.invoke(app, [*TINY, *args])


def _run_dir(out):
    """The one run folder under ``out``."""
    (run,) = out.iterdir()
    return run


def test_tiny_run_prints_a_summary_and_writes_csvs(tmp_path):
    result = _invoke("--out", str(tmp_path), "--no-progress")
    assert result.exit_code == 0, result.output
    for text in ("CV_none, N = 1", "success", "collision", "95 % Wilson interval", "assessment correct"):
        assert text in result.output
    run = _run_dir(tmp_path)
    assert run.name.endswith(STEM)
    scenarios = pd.read_csv(run / "scenarios.csv")
    summary = pd.read_csv(run / "summary.csv")
    info = json.loads((run / "run.json").read_text())
    assert info["status"] == "complete" and info["samples"] == 6 and info["seed"] == 3 and info["planner"] == "CV_none"
    assert info["assessment"] == "observed" and info["nominal"] == "expert" and info["preset"] is None
    assert "numpy" in info["versions"] and info["command"].startswith("safelane")
    assert len(scenarios) == 6 and (scenarios["planner"] == "CV_none").all()
    assert {"success", "collision", "safety_violation", "completion_time_s", "n_abort"} <= set(scenarios.columns)
    assert len(summary) == 1 and summary.loc[0, "samples"] == 6
    assert {"success_rate", "success_lo", "success_hi", "collision_hi"} <= set(summary.columns)
    assert not (run / "trace.csv").exists()


def test_same_seed_same_csv(tmp_path):
    for sub in ("a", "b"):
        assert _invoke("--out", str(tmp_path / sub), "--no-progress").exit_code == 0
    first, second = (pd.read_csv(_run_dir(tmp_path / sub) / "scenarios.csv") for sub in ("a", "b"))
    pd.testing.assert_frame_equal(first, second)


def test_trace_writes_one_scenario_and_a_png(tmp_path):
    result = _invoke("--out", str(tmp_path), "--trace", "--p-v", "0.1", "--assessment", "truth")
    assert result.exit_code == 0, result.output
    run = _run_dir(tmp_path)
    trace = pd.read_csv(run / "trace.csv")
    assert trace["scenario_id"].nunique() == 1 and len(trace) == 100
    assert {"t", "ego_y", "ego_vx", "behaviour", "l1_v", "f_v"} <= set(trace.columns)
    png = (run / "trace.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    assert f"wrote {run / 'trace.png'}" in result.output.replace("\n", "")
    assert json.loads((run / "run.json").read_text())["assessment"] == "truth"


def test_params_file_is_used(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text("p_m: 9.0\n")
    result = _invoke("--out", str(tmp_path / "out"), "--no-progress", "--params", str(params))
    assert result.exit_code == 0, result.output
    scenarios = pd.read_csv(_run_dir(tmp_path / "out") / "scenarios.csv")
    assert (scenarios["min_gap_leader_m"].dropna() >= 9.0 - 1e-9).all()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--planner", "CV_bogus"], "unknown planner variant"),
        (["--p-v", "2"], "p_v"),
        (["--samples", "0"], "samples must be a positive integer"),
        (["--assessment", "oracle"], "assessment"),
    ],
)
def test_bad_options_are_clear_errors(tmp_path, args, message):
    result = runner.invoke(app, [*TINY, "--out", str(tmp_path), *args])
    assert result.exit_code == 2
    assert message in result.output


def test_bad_params_file_is_a_clear_error(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text("p_m: 7.0\nbogus_key: 1\n")
    result = _invoke("--out", str(tmp_path), "--params", str(params))
    assert result.exit_code == 2 and "bogus_key" in result.output
    missing = _invoke("--out", str(tmp_path), "--params", str(tmp_path / "nope.yaml"))
    assert missing.exit_code == 2 and "not found" in missing.output


def test_help_lists_the_options():
    result = runner.invoke(app, ["simulate", "--help"])
    assert result.exit_code == 0
    for option in ("--planner", "--leaders", "--decel", "--samples", "--seed", "--p-v", "--params", "--out", "--trace"):
        assert option in result.output


def test_preset_and_nominal_planner(tmp_path):
    from safelane.experiments.calibration import load_preset
    from safelane.sim import simulate

    result = _invoke("--preset", "paper", "--nominal", "expert", "--out", str(tmp_path), "--no-progress")
    assert result.exit_code == 0, result.output
    got = pd.read_csv(_run_dir(tmp_path) / "scenarios.csv")
    info = json.loads((_run_dir(tmp_path) / "run.json").read_text())
    # With a preset, "expert" is the preset's rule-based planner (its calibrated gains), not ExpertPlanner's defaults.
    assert info["preset"]["name"] == "paper" and info["nominal"] == "expert (preset gains)"
    preset = load_preset("paper")
    want = simulate("CV_none", 1, 4.0, 6, 3, params=preset.params, config=preset.sim, nominal=preset.expert()).table
    assert got["success"].tolist() == want["success"].tolist()
    assert got["completion_time_s"].fillna(-1).tolist() == pytest.approx(want["completion_time_s"].fillna(-1).tolist())


@pytest.mark.parametrize(
    ("args", "hint"),
    [
        (("--preset", "nope"), "not found"),
        (("--nominal", "nope"), "unknown nominal planner"),
        (("--preset", "paper", "--params", "x.yaml"), "either --preset or --params"),
    ],
)
def test_bad_preset_or_nominal(tmp_path, args, hint):
    result = _invoke(*args, "--out", str(tmp_path), "--no-progress")
    assert result.exit_code == 2
    assert hint in result.output


def test_slow_assessment_is_accepted_and_differs_from_observed(tmp_path):
    runs = {}
    for name in ("observed", "slow"):
        result = _invoke("--out", str(tmp_path / name), "--no-progress", "--assessment", name, "--planner", "CV_none")
        assert result.exit_code == 0, result.output
        run = _run_dir(tmp_path / name)
        assert json.loads((run / "run.json").read_text())["assessment"] == name
        runs[name] = pd.read_csv(run / "scenarios.csv")
    # The slow assessment gives its collaborative verdicts later: the first verdict times differ.
    a, b = (runs[n]["assessment_time_s"].fillna(-1.0).to_numpy() for n in ("observed", "slow"))
    assert (a != b).any()
