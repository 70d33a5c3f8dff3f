"""Planner-variant registry and input validation of the simulator's public entry points."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from safelane import Params
from safelane.planners import variants
from safelane.planners.variants import PAPER_VARIANT_NAMES, VARIANT_NAMES, VARIANTS, Variant, get_variant
from safelane.sim import ScenarioConfig, SimConfig, paper_scenarios, simulate, simulate_batch

SHORT = SimConfig(horizon_s=1.0)


def test_registry_holds_every_variant_defined_in_the_module_once():
    defined = [v for v in vars(variants).values() if isinstance(v, Variant)]
    assert not defined  # variants live only in the registry …
    assert VARIANT_NAMES == tuple(VARIANTS)
    assert PAPER_VARIANT_NAMES == VARIANT_NAMES[:4] == ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
    assert all(name == v.name and v.description for name, v in VARIANTS.items())
    flags = {(v.uses_chain, v.uses_follower_v2x, v.uses_assessment, v.rule) for v in VARIANTS.values()}
    assert len(flags) == len(VARIANTS)  # … and each one is a different use of information


@pytest.mark.parametrize("name", VARIANT_NAMES)
def test_every_registered_variant_runs(name):
    assert get_variant(name) is VARIANTS[name]
    table = simulate(name, n_leaders=2, decel=4.0, samples=8, seed=0, config=SHORT).table
    assert len(table) == 8 and (table["planner"] == name).all()
    assert table[["n_proceed", "n_hesitate", "n_abort"]].to_numpy().sum() > 0


def test_variants_rank_as_in_the_paper():
    # Same scenarios (common random numbers) for each variant; non-connected followers so the F information
    # differs, N = 5 so the chain helps: more information never lowers the success rate.
    mixed = ScenarioConfig(follower_connected_share=0.5, follower_aggressive_share=0.3)
    rates = [simulate(name, 5, 6.0, 120, seed=5, scenario=mixed).table["success"].mean()
             for name in PAPER_VARIANT_NAMES]  # fmt: skip
    assert rates == sorted(rates, reverse=True)
    assert rates[0] > rates[-1]


def test_unknown_variant_is_a_clear_error():
    with pytest.raises(ValueError, match=r"unknown planner variant 'CV_al'; choose one of CV_all, CV_follow"):
        get_variant("CV_al")
    with pytest.raises(ValueError, match="unknown planner variant"):
        simulate("cv_all", samples=2)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(samples=-5), "samples must be a positive integer"),
        (dict(samples=0), "samples must be a positive integer"),
        (dict(samples=2.5), "samples must be a positive integer"),
        (dict(decel=math.nan), r"decel \(a_x_N\+1_d\) must be a positive finite number"),
        (dict(decel=math.inf), "positive finite"),
        (dict(decel=-2.0), "positive finite"),
        (dict(planner="CV_everything"), "unknown planner variant"),
        (dict(p_v=-0.01), r"p_v \(promise-violation rate\) must lie in \[0, 1\]"),
        (dict(p_v=1.5), r"must lie in \[0, 1\]"),
        (dict(p_v=math.nan), r"must lie in \[0, 1\]"),
        (dict(n_leaders=-1), "n_leaders must be a non-negative integer"),
        (dict(n_leaders=1.5), "n_leaders must be a non-negative integer"),
    ],
)
def test_bad_simulate_inputs_raise_clear_value_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        simulate(**{"samples": 2, **kwargs})


@pytest.mark.parametrize(
    ("field", "value"),
    [("horizon_s", 0.0), ("sensor_noise_std", -0.1), ("assessment", "oracle"), ("assess_window", 1), ("bogus", 1)],
)
def test_bad_sim_config_is_rejected(field, value):
    with pytest.raises(ValueError, match=field):
        SimConfig(**{field: value})


def test_bad_scenario_config_is_rejected():
    with pytest.raises(ValueError, match="follower_aggressive_share"):
        ScenarioConfig(follower_aggressive_share=1.5)
    with pytest.raises(ValueError, match="traffic_speed"):
        ScenarioConfig(traffic_speed=math.nan)


def test_bad_batches_are_rejected():
    batch = paper_scenarios("CV_all", 1, 4.0, 3, np.random.default_rng(0))
    with pytest.raises(ValueError, match="ego_vx must be >= 0"):
        simulate_batch(dataclasses.replace(batch, ego_vx=-batch.ego_vx))
    with pytest.raises(ValueError, match="speeds v must be >= 0"):
        simulate_batch(dataclasses.replace(batch, v=-batch.v))
    with pytest.raises(ValueError, match="empty"):
        simulate_batch(batch.take(np.zeros(3, bool)))


def test_braking_beyond_the_assumed_worst_case_warns():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        simulate("CV_all", 1, 9.0, 2, config=SHORT, params=Params())
    assert any("exceeds the others' maximum braking params.a_o_d" in str(w.message) for w in caught)
