"""A preset's ``network`` (issue 12): the paper preset's experiments run the network distilled from its rule-based
planner; calibration and distillation use the rule-based planner itself."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml

from safelane import Params
from safelane.errors import InputError
from safelane.experiments.grid import Cell, run_cells
from safelane.experiments.registry import EXPERIMENTS
from safelane.experiments.runner import run_experiment
from safelane.planners import MLPPlanner
from safelane.planners.base import ExpertPlanner
from safelane.planners.registry import get_nominal
from safelane.sim.preset import PRESET_DIR, install_preset, load_preset


def test_the_paper_preset_runs_its_distilled_network_and_keeps_the_rule_based_planner():
    preset = load_preset("paper")
    assert preset.network == "mlp_paper"
    assert isinstance(preset.nominal(), MLPPlanner)
    expert = preset.expert()
    assert isinstance(expert, ExpertPlanner)
    assert all(getattr(expert, k) == v for k, v in preset.planner.items())
    # A preset without a network runs its rule-based planner.
    numbers = load_preset("paper_numbers")
    assert numbers.network is None and isinstance(numbers.nominal(), ExpertPlanner)


def test_a_preset_naming_an_unknown_network_fails_naming_the_file_and_the_value(tmp_path):
    data = yaml.safe_load((PRESET_DIR / "paper.yaml").read_text())
    data["network"] = "resnet9000"
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError, match=r"bad\.yaml: network 'resnet9000' is not a nominal planner.*mlp_paper"):
        load_preset(path)


def test_the_network_survives_writing_and_installing_the_preset(tmp_path):
    preset = load_preset("paper")
    again = tmp_path / "again.yaml"
    again.write_text(preset.to_yaml())
    assert load_preset(again).network == "mlp_paper"
    assert load_preset(install_preset(preset, "mine", folder=tmp_path / "user")).network == "mlp_paper"
    without = tmp_path / "without.yaml"
    without.write_text(load_preset("paper_numbers").to_yaml())
    assert "network" not in yaml.safe_load(without.read_text())


def test_table1_runs_the_network_and_table1_rules_the_rule_based_planner():
    preset = load_preset("paper")
    cfg = EXPERIMENTS["table1"].config_type(samples=12, n_leaders=(1,), decels=(4.0,))
    reported = run_experiment("table1", cfg, preset=preset, seed=3).table.drop(columns="cell")
    cells = [Cell(p, 1, 4.0) for p in cfg.planners]
    by_net = run_cells(cells, 12, 3, params=preset.params, config=preset.sim, nominal=get_nominal("mlp_paper"))
    pd.testing.assert_frame_equal(reported, by_net.drop(columns="cell"))
    rules_cfg = EXPERIMENTS["table1_rules"].config_type(samples=12, n_leaders=(1,), decels=(4.0,))
    rules = run_experiment("table1_rules", rules_cfg, preset=preset, seed=3).table
    by_rules = run_cells(cells, 12, 3, params=preset.params, config=preset.sim, nominal=preset.expert())
    pd.testing.assert_frame_equal(rules.reset_index(drop=True), by_rules.reset_index(drop=True))


def test_the_shipped_network_was_distilled_from_the_shipped_presets_planner():
    # A stale network (paper.yaml re-calibrated, mlp_paper not retrained) fails here: the network records the
    # teacher preset's values it imitated (safelane train --config src/safelane/models/distill_paper.yaml).
    preset = load_preset("paper")
    teacher = get_nominal(preset.network).metadata["teacher_preset"]
    assert teacher["name"] == "paper"
    assert teacher["planner"] == preset.planner
    # Read back as Params today: a field added since (with a default that keeps the old world, e.g. the others'
    # braking limit a_o_d = None, i.e. a_x_d) does not make the network stale; a changed value does.
    assert Params(**teacher["params"]) == preset.params


def test_the_network_imitates_the_rule_based_planner_on_fresh_states():
    # Independent of the training run's own validation split: fresh states of the training distribution (another
    # seed) through both planners; the network stays within 0.05 m/s² of the rules on all but a sliver of them.
    from safelane.training.data import DataConfig, sample_observations

    preset = load_preset("paper")
    obs = sample_observations(4000, np.random.default_rng(7), preset.params, DataConfig())
    net, rules = preset.nominal()(obs, preset.params), preset.expert()(obs, preset.params)
    for head, (a, b) in zip(("a_x", "a_y"), zip(net, rules, strict=True), strict=True):
        err = np.abs(np.asarray(a) - np.asarray(b))
        assert np.sqrt(np.mean(err**2)) < 0.02, head
        assert np.mean(err > 0.05) < 0.01, head


@pytest.mark.parametrize(("extra", "recorded"), [((), "mlp_paper"), (("--nominal", "expert"), "expert (preset gains)"),
                                                 (("--nominal", "mlp"), "mlp")])  # fmt: skip
def test_simulate_records_which_nominal_planner_ran(tmp_path, extra, recorded):
    import json

    from typer.testing import CliRunner

    from safelane.cli import app

    args = ["simulate", "--planner", "CV_all", "--leaders", "1", "--decel", "4", "--samples", "3", "--no-progress",
            "--preset", "paper", "--out", str(tmp_path), *extra]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    (run,) = tmp_path.iterdir()
    assert json.loads((run / "run.json").read_text())["nominal"] == recorded
