"""A preset's ``network`` (issue 12): the paper preset's experiments run the network distilled from its rule-based
planner; calibration and distillation use the rule-based planner itself."""

from __future__ import annotations

import pandas as pd
import pytest
import yaml

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
