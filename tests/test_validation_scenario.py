"""Issue 31: ScenarioConfig refuses physically impossible distributions at construction (field, value, bound)."""

from __future__ import annotations

import warnings

import pytest

from safelane.sim import ScenarioConfig


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(gap=(1.0, 2.0)), r"gap=\(1.0, 2.0\): the lower bound must be >= 2.5 m .*shorter than any car"),
        (dict(promise_decel=100.0), r"promise_decel\n.*less than or equal to 15"),
        (dict(promise_accel=40.0), r"promise_accel\n.*less than or equal to 15"),
        (dict(ego_speed=(29.0, 300.0)), r"ego_speed=\(29.0, 300.0\): the upper bound must be <= 100.0 m/s"),
        (dict(traffic_speed=250.0), r"traffic_speed\n.*less than or equal to 100"),
    ],
)
def test_scenario_config_refuses_impossible_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ScenarioConfig(**kwargs)


def test_scenario_config_names_the_field_through_the_api():
    from safelane.errors import InputError
    from safelane.sim import simulate

    with pytest.raises(InputError, match=r"scenario: field 'promise_decel' = 100.0: Input should be less .* 15"):
        simulate("CV_all", 1, 4.0, 2, 0, scenario={"promise_decel": 100.0})


def test_scenario_config_keeps_the_paper_defaults_and_the_overlap_study():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert ScenarioConfig().gap == (17.0, 22.0)
        # Below params.vehicle_length but not below any car: accepted here, warned about by a run (the overlap study).
        assert ScenarioConfig(gap=(4.0, 4.5)).gap == (4.0, 4.5)
        assert ScenarioConfig(promise_decel=9.0).promise_decel == 9.0  # a run checks it against its a_x_d
