"""Dispatch never guesses (the compiled closed loop, :mod:`safelane.sim._fused`): the cases are built from
:class:`SimConfig`'s own field list, so a setting added to the config without a decision about the compiled loop
fails here, and a setting the loop does not implement can never run compiled as if it were at its default.

For every field, one non-default value: a field the loop implements at one value only (``FIXED``) sends the run
period by period, saying why (``SimResult.engine_reasons``); any other field's value runs compiled and gives the NumPy
path's table bit for bit (so a field wrongly declared as read or as irrelevant is caught by the table)."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.errors import InputError
from safelane.planners.base import ExpertPlanner
from safelane.sim import ScenarioConfig, SimConfig, _fused, concat, paper_scenarios, simulate_batch
from safelane.sim.preset import load_preset
from test_fast_core import needs_numba

pytestmark = [pytest.mark.compiled, needs_numba, pytest.mark.filterwarnings("ignore:a_x_N\\+1_d")]

#: One valid non-default value for every SimConfig field (and what else it needs to be valid).
ALTERNATIVES = {
    "horizon_s": 6.0, "brake_start_s": 0.7, "shield.assessment": "truth", "shield.assess_delay_s": 0.5,
    "shield.assess_miss": 0.3, "shield.completion": "paper_body_across", "sensor_noise_std": 0.3,
    "shield.assess_window": 7, "shield.assess_threshold": 0.35, "follower_open_decel": 1.0, "follower_open_gap_m": 5.0,
    "l1_plan_steps": 4, "shield.enabled": False, "v2x_loss": 0.2, "v2x_latency_periods": 2, "v2x_max_age_s": 0.0,
    "leader_rule": "reactive", "follower_ignores_ego": True, "shield.monitor": False, "own_lane": True,
    "l0_gap_min_m": 5.0, "l0_gap_max_m": 80.0, "l0_speed_spread_mps": 1.0, "l0_decel_mps2": 4.0,
    "l0_brake_window_s": 1.0, "sensing_error": True, "sense_connected_pos_m": 0.1, "sense_connected_speed_mps": 0.05,
    "sense_sensed_pos_m": 2.0, "sense_sensed_speed_mps": 1.0, "sensing_edge_share": 0.5, "actuation_delay_s": 0.1,
    "shield.actuation_delay_s": 0.1, "shield.own_lane": False, "shield.sensing": False, "neighbours": True,
    "neighbour_headway_min_s": 0.5, "neighbour_headway_max_s": 4.0, "neighbour_speed_spread_mps": 1.0,
    "own_lane_connected": 2, "own_promise_decel": 1.0,
}  # fmt: skip


def _config(name: str, **extra) -> SimConfig:
    """SimConfig with setting ``name`` (``shield.x``: the shield's) at its alternative value."""
    value = ALTERNATIVES[name]
    if name.startswith("shield."):
        return SimConfig(shield={name.removeprefix("shield."): value}, **extra)
    return SimConfig(**{name: value}, **extra)


def _batch():
    """Aggressive and collaborative F, connected or not, and an L(N+1) braking beyond ``a_x_d`` (breaches)."""
    cfg = ScenarioConfig(follower_connected_share=0.5)
    cells = (("CV_all", 2, 5.0), ("CV_follow", 2, 5.0), ("CV_none", 1, 9.0))
    return concat([paper_scenarios(v, n, a, 40, np.random.default_rng(k), cfg, first_id=1000 * k)
                   for k, (v, n, a) in enumerate(cells)])  # fmt: skip


def test_every_config_field_has_a_value_here_and_a_decision_in_the_dispatch():
    assert set(ALTERNATIVES) == set(_fused.config_fields(SimConfig)), "a new SimConfig field needs a case here"
    assert _fused.unclassified(SimConfig) == []
    for name, value in ALTERNATIVES.items():
        assert _fused.setting(SimConfig(), name) != value and _fused.setting(_config(name), name) == value, name


def test_a_field_the_dispatch_does_not_classify_is_refused_loudly():
    class Extended(SimConfig):
        new_knob: float = 1.0

    assert _fused.unclassified(Extended) == ["new_knob"]
    with pytest.raises(RuntimeError, match="new_knob"):
        _fused.reasons(_batch(), Extended(), ExpertPlanner(), None, False, False)
    with pytest.raises(RuntimeError, match="new_knob"):
        simulate_batch(_batch(), seed=1, config=Extended())


@pytest.mark.parametrize("name", sorted(_fused.FIXED))
def test_a_setting_the_loop_does_not_implement_runs_period_by_period_and_says_why(monkeypatch, name):
    for env in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(env, raising=False)
    calls = []
    real = _fused.run_chunk
    monkeypatch.setattr(_fused, "run_chunk", lambda *a: calls.append(1) or real(*a))
    cfg = _config(name)
    result = simulate_batch(_batch(), seed=3, config=cfg)
    assert calls == []
    assert result.engine == "period by period"
    assert any(reason.startswith(f"config.{name}=") for reason in result.engine_reasons), result.engine_reasons
    monkeypatch.setenv("SAFELANE_REQUIRE_COMPILED", "1")
    with pytest.raises(InputError, match=f"config.{name}="):
        simulate_batch(_batch(), seed=3, config=cfg)


@pytest.mark.parametrize("name", sorted(_fused.READ | set(_fused.ONLY_WITH)))
def test_a_setting_the_loop_reads_or_that_cannot_act_runs_compiled_with_the_numpy_paths_table(monkeypatch, name):
    for env in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(env, raising=False)
    cfg = _config(name)
    batch = _batch()
    compiled = simulate_batch(batch, seed=3, config=cfg)
    assert compiled.engine == "compiled loop", compiled.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = simulate_batch(batch, seed=3, config=cfg)
    assert reference.engine == "period by period"
    assert compiled.table.equals(reference.table), name


@pytest.mark.parametrize("name", sorted(_fused.FIXED))
def test_each_setting_the_loop_does_not_implement_changes_this_batchs_table(monkeypatch, name):
    """The batch is sensitive to every FIXED field, so declaring one of them READ would fail the test above."""
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    default = simulate_batch(_batch(), seed=3).table
    changed = simulate_batch(_batch(), seed=3, config=_config(name))
    assert not changed.table.equals(default), name


def test_the_reasons_name_every_cause_outside_the_config(monkeypatch):
    monkeypatch.delenv("SAFELANE_NO_FUSED", raising=False)
    small = paper_scenarios("CV_all", 1, 4.0, 8, np.random.default_rng(0))
    why = _fused.reasons(small, SimConfig(), object(), object(), True, True)
    text = " | ".join(why)
    for cause in ("trace", "observations", "traffic model", "fewer than", "nominal planner object"):
        assert cause in text, cause
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    assert "SAFELANE_NO_FUSED=1" in _fused.reasons(_batch(), SimConfig(), ExpertPlanner(), None, False, False)


def test_the_others_maximum_braking_apart_from_a_x_d_runs_compiled(monkeypatch):
    """The compiled loop takes the ego's ``a_x_d`` and the others' maximum ``a_o_d`` apart: ``Params.a_o_d`` set
    runs compiled (its table against the NumPy path: ``tests/test_fast_loop.py``), and set equal to ``a_x_d`` it
    gives the unset table."""
    for env in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(env, raising=False)
    harder = simulate_batch(_batch(), seed=3, params=Params(a_o_d=9.5))
    assert harder.engine == "compiled loop", harder.engine_reasons
    same = simulate_batch(_batch(), seed=3, params=Params(a_o_d=Params().a_x_d))
    assert same.engine == "compiled loop", same.engine_reasons
    assert same.table.equals(simulate_batch(_batch(), seed=3).table)
    assert not harder.table.equals(same.table)  # the others' braking reaches the table


@pytest.mark.parametrize(("name", "value"), [(n, v) for n in sorted(_fused.FIXED) for v in _fused.implemented(n)[1:]])
def test_every_other_value_the_loop_implements_runs_compiled_with_the_numpy_paths_table(monkeypatch, name, value):
    """On the paper preset's vehicles, where the paper's completion rule changes outcomes (its crossings are checked
    by the evasion alone)."""
    for env in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(env, raising=False)
    field = name.removeprefix("shield.")
    extra = {"assess_delay_s": 3.0, "assess_miss": 0.231} if value == "slow" else {}  # (the paper preset's)
    cfg = SimConfig(shield={field: value, **extra}) if name.startswith("shield.") else SimConfig(**{name: value})
    prm = load_preset("paper").params
    cells = (("CV_all", 3, 6.0), ("CV_none", 1, 6.0), ("No_agg_assess", 3, 6.0), ("CV_follow", 1, 5.0))
    mixed = ScenarioConfig(follower_connected_share=0.5)
    batch = concat([paper_scenarios(v, n, a, 100, np.random.default_rng(k), mixed, first_id=1000 * k)
                    for k, (v, n, a) in enumerate(cells)])  # fmt: skip
    compiled = simulate_batch(batch, seed=3, params=prm, config=cfg)
    assert compiled.engine == "compiled loop", compiled.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = simulate_batch(batch, seed=3, params=prm, config=cfg)
    assert compiled.table.equals(reference.table), name
    assert not reference.table.equals(simulate_batch(batch, seed=3, params=prm).table), "the value changes nothing"
