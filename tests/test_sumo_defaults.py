"""SUMO (issue 31): ``SumoRunner`` and ``safelane sumo`` run the same nominal planner by default (one source,
:func:`safelane.integrations.sumo.default_policy`), ``--nominal`` takes a name or a model file, and
``SumoRunner.settings()`` works after the ``with`` block (and says when it can be called before the first run).

libsumo allows one simulation per process: every test here opens and closes its own runner in turn.
"""

from __future__ import annotations

import json
import shutil
from importlib.resources import files

import pandas as pd
import pytest
from typer.testing import CliRunner

from safelane.cli import app

pytest.importorskip("libsumo", reason="libsumo is not installed: pip install 'safelane[sumo]' (make install does)")

from safelane.integrations import sumo
from safelane.integrations.sumo_cells import cell_scenarios, run_episodes
from safelane.planners.base import ExpertPlanner

cli = CliRunner()
# A cell where the reckless merge and the expert planner differ (N = 1, L2 braking at 8 m/s², unshielded).
CELL = dict(planner="CV_all", n_leaders=1, decel=8.0, episodes=4, seed=0)


def _rows(results) -> pd.DataFrame:
    return pd.DataFrame([r.results_row("CV_all") for r in results]).drop(columns=["wall_s"], errors="ignore")


def test_runner_default_policy_is_the_expert_as_in_safelane_sumo():
    with sumo.SumoRunner() as runner:
        policy = runner.policy
        assert isinstance(policy, sumo.NominalPolicy) and type(policy.planner) is ExpertPlanner
        assert policy.planner == ExpertPlanner() and policy.l1_plan_steps == 10 and policy.uses_chain
    assert sumo.DEFAULT_NOMINAL == "expert"


def test_runner_and_run_episodes_give_the_same_numbers_by_default():
    """Same cell, same seed: ``SumoRunner()`` (Python) and ``run_episodes`` (what ``safelane sumo`` runs) agree
    row by row, shielded and unshielded (the old Python default, the reckless merge, differs here)."""
    _, scenarios = cell_scenarios(**CELL)
    tables = {}
    for shielded in (True, False):
        with sumo.SumoRunner(seed=CELL["seed"]) as runner:
            python = _rows([runner.run(sc, shielded=shielded) for sc in scenarios])
        tables[shielded] = _rows(run_episodes(scenarios, planner="CV_all", seed=CELL["seed"], shielded=shielded))
        pd.testing.assert_frame_equal(python, tables[shielded])
    with sumo.SumoRunner(seed=CELL["seed"], policy=sumo.reckless) as runner:  # the reckless merge: on request
        reckless = _rows([runner.run(sc) for sc in scenarios])
    # It is another planner: other outcomes in this cell (the expert waits behind L1 in two episodes).
    assert reckless["success"].tolist() != tables[True]["success"].tolist()


def test_settings_after_the_with_block_and_before_the_first_run():
    runner = sumo.SumoRunner()
    with pytest.raises(RuntimeError, match=r"after the first episode.*run\("):
        runner.settings()
    with runner:
        runner.run(sumo.sumo_scenarios(1, 4.0, 1, seed=3)[0])
        inside = runner.settings()
    after = runner.settings()  # the documented snippet: print(runner.settings()) after the with block
    assert after == inside
    assert after["ballistic"] == "true" and after["collision_action"] == "warn"
    assert after["step_length_s"] == pytest.approx(0.1)


def test_cli_nominal_model_file_and_name(tmp_path):
    """``safelane sumo --nominal PATH.npz``: the shipped ``mlp`` network from a file gives the numbers of
    ``--nominal mlp``; run.json names the file."""
    model = tmp_path / "model.npz"
    shutil.copyfile(str(files("safelane") / "models" / "mlp_default.npz"), model)
    base = ["sumo", "--leaders", "1", "--decel", "4", "--episodes", "2", "--seed", "1", "--no-progress"]
    tables = {}
    for nominal in ("mlp", str(model)):
        out = tmp_path / ("by-name" if nominal == "mlp" else "by-file")
        result = cli.invoke(app, [*base, "--nominal", nominal, "--out", str(out)])
        assert result.exit_code == 0, result.output
        assert f"nominal {nominal}" in " ".join(result.output.split())
        (run,) = out.iterdir()
        assert run.name.endswith("-mlp" if nominal == "mlp" else "-model")  # the name, or the file's name
        assert json.loads((run / "run.json").read_text())["nominal"] == nominal
        tables[nominal] = pd.read_csv(run / "scenarios.csv").drop(columns=["wall_s"], errors="ignore")
    pd.testing.assert_frame_equal(tables["mlp"], tables[str(model)])


@pytest.mark.parametrize(
    ("value", "message"),
    [("missing.npz", "model file not found"), ("bogus", "unknown nominal planner 'bogus'")],
)
def test_cli_bad_nominal_names_the_option_and_file(tmp_path, value, message):
    result = cli.invoke(app, ["sumo", "--episodes", "1", "--nominal", value, "--out", str(tmp_path)])
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert "--nominal" in text and message in text and value in text
    assert not any(tmp_path.iterdir())
