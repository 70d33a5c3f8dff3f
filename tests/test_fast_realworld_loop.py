"""The realistic world's side in the compiled closed loop (:mod:`safelane.sim._fast_loop`, its rows
``sim/_fast_world.py``) against the loop period by period (``SAFELANE_NO_FUSED=1``): the same per-scenario table,
column for column and bit for bit, with the own lane's leader ``L0`` (its profile motion, the ego's exact checks
against it, the shield's own lane on and off), with sensing error (the measurement draws, with and without the edge
share; the shield's sensing off: it takes the measurements as exact) and both together — each on a batch where the
feature changes the outcome, so that the comparison can fail. And the dispatch: what the loop does not run yet (a
shield's delay other than the world's) runs period by period, saying why. The shield's sensing and delay in the loop:
``tests/test_fast_realistic_loop.py``; a connected own lane (a chain ahead of ``L0``):
``tests/test_fast_own_chain_loop.py``."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.planners.base import ExpertPlanner
from safelane.sim import ScenarioConfig, SimConfig, _fused, concat, paper_scenarios, simulate_batch
from safelane.sim._stepper import steps_compiled
from safelane.sim.preset import load_preset
from test_fast_core import needs_numba

pytestmark = [pytest.mark.compiled, needs_numba, pytest.mark.filterwarnings("ignore:a_x_N\\+1_d")]

VARIANTS = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
MIXED_F = ScenarioConfig(follower_connected_share=0.5)
#: The realistic preset's vehicles (others brake up to a_o_d = 9.5).
REALISTIC = load_preset("realistic").params


def _mixed(n_leaders, decel, per_variant=60, seed=0):
    return concat([paper_scenarios(v, n_leaders, decel, per_variant, np.random.default_rng(100 * seed + k), MIXED_F,
                                   first_id=1000 * k) for k, v in enumerate(VARIANTS)])  # fmt: skip


def _two_paths(monkeypatch, batch, **kwargs):
    """``(compiled loop, period by period)`` tables and how often the compiled loop ran."""
    calls = []
    real = _fused.run_chunk
    monkeypatch.setattr(_fused, "run_chunk", lambda *a: calls.append(1) or real(*a))
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    fused = simulate_batch(batch, seed=4, **kwargs)
    assert fused.engine == "compiled loop", fused.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, **kwargs)
    assert periods.engine == "period by period"
    return fused.table, periods.table, len(calls)


#: An own-lane leader near and braking early (collisions and p_m violations against it where the shield ignores it).
NEAR_L0 = dict(own_lane=True, l0_gap_min_m=6.0, l0_gap_max_m=30.0, l0_brake_window_s=2.0)

CASES = {
    "own lane: L0, the shield's own lane on": (
        lambda: _mixed(3, 5.0),
        dict(params=REALISTIC, config=SimConfig(**NEAR_L0)),
        "own",
    ),
    "own lane: L0, the shield ignores it": (
        lambda: _mixed(3, 5.0, seed=1),
        dict(params=REALISTIC, config=SimConfig(**NEAR_L0, shield={"own_lane": False})),
        "own",
    ),
    "own lane: L0 by the default distribution, slow assessment, reactive leaders": (
        lambda: _mixed(2, 7.0, seed=2),
        dict(
            params=REALISTIC,
            config=SimConfig(
                own_lane=True, leader_rule="reactive", assessment="slow", assess_delay_s=2.388, assess_miss=0.259
            ),
        ),
        "own",
    ),
    "sensing error, the shield takes the measurements as exact": (
        lambda: _mixed(3, 5.0, seed=3),
        dict(
            params=REALISTIC,
            config=SimConfig(
                sensing_error=True, sense_sensed_pos_m=2.0, sense_sensed_speed_mps=1.0, shield={"sensing": False}
            ),
        ),
        "sensing",
    ),
    "sensing error with the edge share, N = 5": (
        lambda: _mixed(5, 6.0, seed=4),
        dict(params=REALISTIC, config=SimConfig(sensing_error=True, sensing_edge_share=0.5, shield={"sensing": False})),
        "sensing",
    ),
    "own lane and sensing error": (
        lambda: _mixed(3, 6.0, seed=5),
        dict(params=REALISTIC, config=SimConfig(**NEAR_L0, sensing_error=True, shield={"sensing": False})),
        "both",
    ),
    "actuation delay 0.2 s (the shield's off: it decides as if its commands acted at once)": (
        lambda: _mixed(3, 5.0, seed=7),
        dict(params=REALISTIC, config=SimConfig(actuation_delay_s=0.2, shield_delay=False)),
        "delay",
    ),
    "actuation delay 0.1 s, N = 1, a_N+1 = 9 (aborts on the held plan executed late)": (
        lambda: _mixed(1, 9.0, seed=8),
        dict(config=SimConfig(actuation_delay_s=0.1, shield_delay=False)),
        "delay",
    ),
    "the realistic preset's world (own lane, sensing error, delay 0.2 s; its shield's sensing and delay off)": (
        lambda: _mixed(3, 6.0, seed=9),
        dict(
            params=REALISTIC,
            config=SimConfig(
                **NEAR_L0,
                sensing_error=True,
                actuation_delay_s=0.2,
                shield_delay=False,
                shield_sensing=False,
                assessment="slow",
                assess_delay_s=2.388,
                assess_miss=0.259,
            ),
            nominal=ExpertPlanner(k_p=0.728, k_v=0.023, omega=0.732, gap_fraction=0.441, brake_comfort=6.296),
        ),
        "all",
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_compiled_loop_runs_the_realistic_world_with_the_period_by_period_table(monkeypatch, case):
    make, kwargs, feature = CASES[case]
    batch = make()
    fused, periods, calls = _two_paths(monkeypatch, batch, **kwargs)
    assert calls == 1
    assert fused.equals(periods), case
    assert (periods[["n_proceed", "n_hesitate", "n_abort"]].sum() > 0).all()
    if feature in ("own", "both", "all"):  # L0 is in the table and comes near: its checks can fail the comparison
        gap = periods["min_gap_own_lane_m"]
        assert gap.notna().any() and (gap < 2 * REALISTIC.p_m).sum() > 5, gap.describe()
        if "ignores" in case:
            assert periods["own_lane_collision"].any() and periods["own_lane_violation"].any()
    # the feature changes the outcome: without it the table differs
    cfg = kwargs["config"]
    off = {"own": dict(own_lane=False), "delay": dict(actuation_delay_s=0.0)}.get(feature, dict(sensing_error=False))
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    without = simulate_batch(batch, seed=4, **{**kwargs, "config": cfg.model_copy(update=off)}).table
    cols = [
        "n_proceed",
        "n_hesitate",
        "n_abort",
        "min_gap_follower_m",
        "completion_time_s",
        "collision",
        "safety_violation",
    ]
    changed = ~(without[cols].fillna(-1.0).to_numpy() == periods[cols].fillna(-1.0).to_numpy()).all(1)
    assert changed.sum() > len(batch) // 20, changed.sum()
    if feature == "delay":  # the aborts' plans executed a period or two late: the delay reaches the held plan's path
        assert periods["n_abort"].sum() > 0


def test_the_numpy_path_gives_the_same_table_with_the_own_lane_and_sensing(monkeypatch):
    """The compiled loop against the NumPy path itself (``SAFELANE_NO_NUMBA=1``) on a smaller batch."""
    batch = _mixed(3, 6.0, per_variant=20, seed=6)
    kwargs = dict(params=REALISTIC, config=SimConfig(**NEAR_L0, sensing_error=True, sensing_edge_share=0.3,
                                                     shield={"sensing": False}))  # fmt: skip
    monkeypatch.delenv("SAFELANE_NO_FUSED", raising=False)
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fused = simulate_batch(batch, seed=4, **kwargs)
    assert fused.engine == "compiled loop", fused.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    assert fused.table.equals(simulate_batch(batch, seed=4, **kwargs).table)


REFUSED = {
    "the shield's delay other than the world's": (
        SimConfig(actuation_delay_s=0.2, shield={"actuation_delay_s": 0.1}),
        "config.shield.actuation_delay_s=0.1",
    ),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_what_the_loop_does_not_run_yet_runs_period_by_period_and_says_why(monkeypatch, case):
    cfg, reason = REFUSED[case]
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    why = _fused.reasons(_mixed(1, 5.0, per_variant=20), cfg, ExpertPlanner(), None, False, False)
    assert any(r.startswith(reason) for r in why), why


def test_the_realistic_world_without_its_shield_sides_runs_compiled(monkeypatch):
    """The realistic preset's config with the shield's sensing and delay off (what this loop runs) is covered, in the
    loop and stepped from Python (the envs); with the shield's sides on too (``tests/test_fast_realistic_loop.py``,
    ``tests/test_env_realworld.py``), but for a shield's delay other than the world's, which the envs name."""
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    cfg = load_preset("realistic").sim
    assert cfg.actuation_delay_s > 0.0 and cfg.own_lane and cfg.sensing_error
    cfg = cfg.model_copy(update=dict(shield=cfg.shield.model_copy(update=dict(sensing=False, actuation_delay_s=0.0))))
    assert _fused.reasons(_mixed(1, 5.0, per_variant=20), cfg, ExpertPlanner(), None, False, False) == []
    assert steps_compiled(_mixed(1, 5.0), cfg, None) == []
    whole = load_preset("realistic").sim
    assert whole.shield.sensing and whole.shield.actuation_delay_s == whole.actuation_delay_s
    assert steps_compiled(_mixed(1, 5.0), whole, None) == []
    other = whole.model_copy(update=dict(shield=whole.shield.model_copy(update=dict(actuation_delay_s=0.1))))
    why = steps_compiled(_mixed(1, 5.0), other, None)
    assert any(r.startswith("config.shield.actuation_delay_s=0.1") for r in why), why


def test_the_compiled_period_stepped_from_python_runs_the_own_lane_and_sensing(monkeypatch):
    """A nominal planner the loop does not run (a subclass of the expert) steps the compiled period from Python
    (``sim/_stepper.Stepper``, engine ``"compiled period"``): the own lane, sensing error and the delay there too, with
    the period-by-period table (its final monitor view as measured: ``finish_kernel``); the envs step it too."""
    mine = type("Mine", (ExpertPlanner,), {})()
    cfg = SimConfig(**NEAR_L0, sensing_error=True, sensing_edge_share=0.2, shield_sensing=False, actuation_delay_s=0.1,
                    shield_delay=False)  # fmt: skip
    kwargs = dict(params=REALISTIC, nominal=mine, config=cfg)
    batch = _mixed(3, 6.0, per_variant=30, seed=11)
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    stepped = simulate_batch(batch, seed=4, **kwargs)
    assert stepped.engine == "compiled period", (stepped.engine, stepped.engine_reasons)
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, **kwargs)
    assert periods.engine == "period by period"
    assert stepped.table.equals(periods.table)
    assert periods.table["own_lane_violation"].any()
    monkeypatch.delenv("SAFELANE_NO_FUSED")
    assert steps_compiled(batch, cfg, None) == []


def test_rows_without_l0_a_world_key_and_chunks_give_the_period_by_period_table(monkeypatch):
    """A batch that brings its own ``L0`` (none in every third row: ``+inf``) and the falsifier's key of the world's
    draws (``ScenarioBatch.world_key``), run in chunks behind a progress bar: the period-by-period table."""
    from dataclasses import replace

    from safelane.sim.realworld import with_own_lane

    cfg = SimConfig(**NEAR_L0, sensing_error=True, shield_sensing=False, actuation_delay_s=0.1, shield_delay=False)
    batch = with_own_lane(_mixed(3, 5.0, per_variant=40, seed=12), 4, cfg, REALISTIC)
    l0_x = batch.l0_x.copy()
    l0_x[::3] = np.inf
    batch = replace(batch, l0_x=l0_x, world_key=batch.scenario_id * 7 + 3)
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(_fused, "PROGRESS_CHUNK", 70)
    fused = simulate_batch(batch, seed=4, params=REALISTIC, config=cfg, progress=True)
    assert fused.engine == "compiled loop", fused.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, params=REALISTIC, config=cfg)
    assert fused.table.equals(periods.table)
    gap = periods.table["min_gap_own_lane_m"].to_numpy()
    assert np.isnan(gap[::3]).all() and np.isfinite(gap[1::3]).all()
    other_key = simulate_batch(replace(batch, world_key=None), seed=4, params=REALISTIC, config=cfg).table
    assert not other_key.equals(periods.table)  # the key reaches the draws


#: Sensing error with the shield's sensing off over three periods: the monitor's view after the last period
#: (``ClosedLoop.finish``, ``_fast_loop._seen``) is one of two comparisons, so it decides many rows' breach flags.
FINAL_VIEW = {
    "target lane": (lambda: _mixed(3, 10.0, per_variant=40, seed=3), dict()),
    "with L0 near and the edge share": (lambda: _mixed(2, 10.0, per_variant=40, seed=13),
                                        dict(**NEAR_L0, sensing_edge_share=0.3)),
}  # fmt: skip


@pytest.mark.parametrize("case", list(FINAL_VIEW))
def test_the_final_monitor_view_takes_the_measurements_as_exact_where_the_shields_sensing_is_off(monkeypatch, case):
    """The monitor's view of the last period (after the run) compares the measurements as the shield takes them — as
    exact, with its sensing off, the comparison every period's ``stages.observe`` makes — on every path: the compiled
    loop, the compiled period stepped from Python (``finish_kernel``), period by period and the NumPy path. Before,
    the NumPy paths' ``core.observe`` compared the sensing box's observed corner there (it had no config), and flagged
    fewer breaches than the compiled ones."""
    from safelane.shield import core

    make, update = FINAL_VIEW[case]
    batch = make()
    cfg = SimConfig(sensing_error=True, shield_sensing=False, horizon_s=0.3, **update)
    kwargs = dict(params=REALISTIC, config=cfg)
    fused, periods, _ = _two_paths(monkeypatch, batch, **kwargs)
    assert fused.equals(periods), case
    monkeypatch.delenv("SAFELANE_NO_FUSED")
    stepped = simulate_batch(batch, seed=4, nominal=type("Mine", (ExpertPlanner,), {})(), **kwargs)
    assert stepped.engine == "compiled period", stepped.engine_reasons
    assert stepped.table.equals(periods), case
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    assert simulate_batch(batch, seed=4, **kwargs).table.equals(periods), case
    # the final view decides breach flags here: at the observed corner (the old view) fewer rows are flagged
    flags = [c for c in periods.columns if c.startswith("breach_")]
    real = core.observe
    monkeypatch.setattr(core, "observe", lambda state, situation, params, config=None: real(state, situation, params))
    corner = simulate_batch(batch, seed=4, **kwargs).table
    assert (corner[flags].sum() <= periods[flags].sum()).all()
    assert (corner[flags] != periods[flags]).any(axis=None), periods[flags].sum()
