"""``safelane check`` and ``safelane calibrate`` run for real (no fakes): check against the safety API on the
same state, calibrate on a tiny grid with its outputs checked against each other."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from safelane import Params
from safelane.cli import app
from safelane.safety import plan_evasion, worst_case_leader_decel

PRM = Params()


def _check(*args: str) -> dict:
    result = CliRunner().invoke(app, ["check", *args])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


@pytest.mark.parametrize(
    ("args", "state"),
    [
        # The README's example: a follower 12 m behind, assumed aggressive.
        (["--ego-py", "1.5", "--ego-vy", "0.6", "--f-p", "-12", "--aggressive"],
         dict(ego_py=1.5, ego_vy=0.6, f_p=-12.0, aggressive=True)),
        # Every state option moved off its default, a collaborative follower.
        (["--ego-px", "3", "--ego-py", "1.0", "--ego-vx", "25", "--ego-vy", "-0.2", "--l1-p", "19", "--l1-v", "22",
          "--l1-decel", "5", "--f-p", "-9", "--f-v", "27", "--collaborative"],
         dict(ego_px=3.0, ego_py=1.0, ego_vx=25.0, ego_vy=-0.2, l1_p=19.0, l1_v=22.0, l1_decel=5.0, f_p=-9.0,
              f_v=27.0, aggressive=False)),
        # No evasion: an aggressive follower 8 m behind, much faster.
        (["--ego-py", "1.6", "--ego-vy", "0.8", "--f-p", "-8", "--f-v", "36"],
         dict(ego_py=1.6, ego_vy=0.8, f_p=-8.0, f_v=36.0, aggressive=True)),
    ],
)  # fmt: skip
def test_check_prints_the_plan_the_safety_api_gives_for_the_same_state(args, state):
    out = _check(*args)
    full = dict(ego_px=0.0, ego_py=1.2, ego_vx=30.0, ego_vy=0.5, l1_p=20.0, l1_v=30.0, l1_decel=PRM.a_x_d,
                f_p=-20.0, f_v=30.0, aggressive=True) | state  # the command's defaults  # fmt: skip
    plan = plan_evasion(*full.values(), PRM)
    assert out["evasion_exists"] is bool(plan.feasible)
    assert out["l1_decel"] == full["l1_decel"]
    for key, value in (("t_y_f", plan.t_y_f), ("t_x1", plan.t_x1), ("t_x2", plan.t_x2),
                       ("min_gap_follower_m", plan.min_gap_follower)):  # fmt: skip
        assert out[key] == pytest.approx(float(value), rel=1e-12, abs=1e-12)
    assert out["params"] == PRM.model_dump() and out["preset"] is None
    assert (out["reasons"] == []) is bool(plan.feasible)


def test_check_examples_differ_in_the_verdict():
    assert _check("--ego-py", "1.5", "--ego-vy", "0.6", "--f-p", "-12", "--aggressive")["evasion_exists"] is True
    assert _check("--ego-py", "1.6", "--ego-vy", "0.8", "--f-p", "-8", "--f-v", "36")["evasion_exists"] is False


def test_check_takes_l1s_worst_case_from_the_chain():
    out = _check("--chain-p", "40", "--chain-p", "60", "--chain-v", "30", "--chain-v", "28", "--promise", "1.0")
    expected = float(worst_case_leader_decel([20.0, 40.0, 60.0], [30.0, 30.0, 28.0], [1.0, 1.0], PRM))
    assert out["l1_decel"] == pytest.approx(expected, rel=1e-12) and out["l1_decel"] < PRM.a_x_d


def test_check_with_the_paper_preset_uses_its_params():
    out = _check("--preset", "paper")
    assert out["preset"] == "paper" and set(out["params"]) == set(PRM.model_dump())


def test_calibrate_runs_for_real_on_a_tiny_grid(tmp_path):
    result = CliRunner().invoke(
        app,
        ["calibrate", "--candidates", "1", "--samples", "4", "--refine", "1", "--finalists", "1",
         "--final-samples", "4", "--seed", "0", "--out", str(tmp_path)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    (run,) = tmp_path.iterdir()
    info = json.loads((run / "run.json").read_text())
    assert info["status"] == "complete" and info["kind"] == "calibrate"
    candidates = pd.read_csv(run / "candidates.csv")
    assert len(candidates) == 3 and list(candidates["stage"]) == [1, 1, 2]  # search, refine; the final re-score
    # The loss is what it says: the mean |ours − paper| over the 40 published cells of the fit written beside it.
    fit = pd.read_csv(run / "fit_per_cell.csv")
    assert len(fit) == 40 and set(fit["n_leaders"]) == {1, 10}
    mae = float((fit["success_rate"] - fit["paper_success"]).abs().mean())
    preset = yaml.safe_load((run / "preset.yaml").read_text())
    assert preset["meta"]["loss_mean_abs_diff"] == pytest.approx(mae, abs=5e-4)
    assert info["loss_mean_abs_diff"] == preset["meta"]["loss_mean_abs_diff"]
    assert 0.0 < mae < 1.0 and np.isfinite(candidates["loss"]).all()
    # The preset is the re-scored finalist (the search's best point), and its loss the final stage's.
    final = candidates[candidates["stage"] == 2].iloc[0]
    assert final["loss"] == pytest.approx(mae, abs=5e-4)
    for key in ("a_x_a", "a_x_d", "a_y_m", "p_m"):
        assert preset["params"][key] == pytest.approx(final[key], abs=1e-3)
    assert preset["sim"]["horizon_s"] == pytest.approx(final["horizon_s"], abs=1e-3)
