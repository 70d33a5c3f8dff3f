"""``safelane sumo``: a tiny run in SUMO (libsumo) writes the run folder; bad values fail cleanly, naming the option.

The run tests skip where libsumo is missing; the install-hint test does not need it (it hides libsumo).
"""

from __future__ import annotations

import json
import sys

import pandas as pd
import pytest
from typer.testing import CliRunner

from safelane.cli import app

runner = CliRunner()
TINY = ["sumo", "--leaders", "1", "--decel", "4", "--episodes", "3", "--seed", "2", "--no-progress"]
needs_libsumo = pytest.mark.skipif(
    not __import__("safelane.integrations.sumo_world", fromlist=["x"]).libsumo_available(),
    reason="libsumo is not installed: pip install 'safelane[sumo]' (make install does)",
)


@needs_libsumo
def test_tiny_run_writes_the_run_folder(tmp_path):
    from safelane.sim import simulate

    result = runner.invoke(app, [*TINY, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    for text in ("SUMO, CV_all, N = 1", "success", "collision (ego, SUMO's list)", "95 % Wilson interval"):
        assert text in result.output
    (run,) = tmp_path.iterdir()
    assert run.name.endswith("CV_all_N1_decel4_paper_seed2")
    table = pd.read_csv(run / "scenarios.csv")
    collisions = pd.read_csv(run / "collisions.csv")
    summary = pd.read_csv(run / "summary.csv")
    info = json.loads((run / "run.json").read_text())
    assert info["status"] == "complete" and info["episodes"] == 3 and info["traffic"] == "paper"
    assert info["nominal"] == "expert" and "--step-method.ballistic" in info["sumo_args"]
    assert set(info["files"]) == {"scenarios.csv", "collisions.csv", "summary.csv", "run.json"}
    # The built-in simulator's columns that apply, then SUMO's own.
    builtin = simulate("CV_all", 1, 4.0, 3, 2).table
    shared = {"scenario_id", "planner", "n_leaders", "decel", "success", "collision", "leader_collision",
              "completed", "completion_time_s", "n_proceed", "n_hesitate", "n_abort", "assessment_correct",
              "assumption_breach", "initial_safe"}  # fmt: skip
    assert shared <= set(table.columns) & set(builtin.columns)
    assert {"traffic", "collider", "victim", "geometric_overlap", "promise_violations"} <= set(table.columns)
    # The same scenarios as `safelane simulate` with the same cell and seed: same ids, same outcomes here.
    assert table["scenario_id"].tolist() == builtin["scenario_id"].tolist()
    assert table["success"].tolist() == builtin["success"].tolist()
    assert not table["collision"].any() and collisions.empty
    assert list(collisions.columns)[:5] == ["scenario_id", "collider", "victim", "type", "lane"]
    assert summary.loc[0, "samples"] == 3 and {"success_lo", "success_hi", "collision_hi"} <= set(summary.columns)


@needs_libsumo
def test_unshielded_collisions_go_to_the_collision_list(tmp_path):
    """Without the shield the expert planner, facing L2 braking at 8 m/s², hits someone; SUMO's list says whom."""
    args = ["sumo", "--leaders", "1", "--decel", "8", "--episodes", "4", "--seed", "0", "--no-shield",
            "--no-progress", "--out", str(tmp_path)]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    (run,) = tmp_path.iterdir()
    table = pd.read_csv(run / "scenarios.csv")
    collisions = pd.read_csv(run / "collisions.csv")
    assert len(collisions) > 0 and set(collisions["collider"]) == {"ego"} and table["collision"].any()
    assert int(table["sumo_collisions"].sum()) == len(collisions)
    assert set(collisions["scenario_id"]) == set(table.loc[table["sumo_collisions"] > 0, "scenario_id"])


@pytest.mark.parametrize(
    ("args", "option", "message"),
    [
        (["--traffic", "krauss"], "--traffic", "'krauss' is not one of 'paper', 'sumo'"),
        (["--traffic", ""], "--traffic", "is not one of"),
        (["--episodes", "0"], "--episodes", "episodes must be a positive integer"),
        (["--leaders", "-1"], "--leaders", "n_leaders"),
        (["--decel", "-2"], "--decel", "decel"),
        (["--planner", "CV_bogus"], "--planner", "unknown planner variant"),
        (["--gui", "--workers", "2"], "--workers", "one process"),
    ],
)
def test_bad_values_name_the_option(tmp_path, args, option, message):
    result = runner.invoke(app, ["sumo", *args, "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert option in result.output and message in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_missing_libsumo_is_one_line_with_the_install_hint(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "libsumo", None)  # import libsumo now raises ImportError
    result = runner.invoke(app, ["sumo", "--episodes", "2", "--out", str(tmp_path)])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "pip install 'safelane[sumo]'" in lines[0], result.output
    assert "Traceback" not in result.output and not any(tmp_path.iterdir())
