"""The nominal-planner registry: every registered planner builds and drives a tiny simulation; clear errors."""

from __future__ import annotations

import numpy as np
import pytest

import safelane.planners as planners
from safelane.planners import NOMINAL_NAMES, NOMINAL_PLANNERS, NominalPlanner, get_nominal
from safelane.sim import SimConfig, simulate

TINY = SimConfig(horizon_s=1.0)


@pytest.mark.parametrize("name", NOMINAL_NAMES)
def test_every_registered_nominal_planner_runs_a_tiny_simulation(name):
    planner = get_nominal(name)
    assert isinstance(planner, NominalPlanner)
    table = simulate("CV_all", n_leaders=1, decel=4.0, samples=3, seed=0, config=TINY, nominal=planner).table
    assert len(table) == 3
    assert not table["collision"].any()
    assert table["n_proceed"].sum() + table["n_hesitate"].sum() + table["n_abort"].sum() > 0


def test_registry_names_and_types():
    assert NOMINAL_NAMES == ("expert", "mlp", "teacher", "mlp_paper")
    assert tuple(NOMINAL_PLANNERS) == NOMINAL_NAMES
    assert isinstance(get_nominal("expert"), planners.ExpertPlanner)
    assert isinstance(get_nominal("mlp"), planners.MLPPlanner)
    assert isinstance(get_nominal("teacher"), planners.OptimalControlTeacher)
    assert isinstance(get_nominal("mlp_paper"), planners.MLPPlanner)


def test_every_planner_class_the_package_exports_is_registered():
    exported = {planners.ExpertPlanner, planners.MLPPlanner, planners.OptimalControlTeacher}
    built = {type(get_nominal(name)) for name in NOMINAL_NAMES}
    assert exported <= built


def test_mlp_entry_is_the_shipped_model():
    x = np.zeros((2, planners.load_default_planner().mean.shape[0]))
    np.testing.assert_array_equal(get_nominal("mlp").predict(x), planners.load_default_planner().predict(x))


def test_unknown_name_lists_the_registered_ones():
    with pytest.raises(ValueError, match="unknown nominal planner 'nope'; choose one of expert, mlp, teacher"):
        get_nominal("nope")
