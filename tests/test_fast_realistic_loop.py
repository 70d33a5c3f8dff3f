"""The shield's sensing and actuation delay in the compiled closed loop (:mod:`safelane.sim._fast_loop`): the
``realistic`` preset and variations of it against the loop period by period (``SAFELANE_NO_FUSED=1``) and the NumPy
path (``SAFELANE_NO_NUMBA=1``), the per-scenario table column for column and bit for bit — the sensing box's corners,
the monitor's cumulative anchor held between periods (``_fast_rows.Rows.anc_*``), the final view at the observed
corner, the ego carried over the commands in flight where the shield's delay is the world's — each on a batch where
the feature changes the outcome, so that the comparison can fail. And the dispatch: a shield's delay other than the
world's runs period by period, saying why."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.planners.base import ExpertPlanner
from safelane.sim import ScenarioConfig, SimConfig, _fused, concat, paper_scenarios, simulate_batch
from safelane.sim._stepper import steps_compiled
from safelane.sim.preset import load_preset
from test_fast_core import needs_numba

pytestmark = [pytest.mark.compiled, needs_numba, pytest.mark.filterwarnings("ignore:a_x_N\\+1_d")]

PRESET = load_preset("realistic")
REALISTIC = PRESET.params
MIXED_F = ScenarioConfig(follower_connected_share=0.5)
PAPER_VARIANTS = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
RSS_VARIANTS = ("RSS", "RSS_V2X_matched", "CV_all", "No_agg_assess")
#: An own-lane leader near and braking early.
NEAR_L0 = dict(own_lane=True, l0_gap_min_m=6.0, l0_gap_max_m=30.0, l0_brake_window_s=2.0)
#: Wide sensing bounds (the box's corners and the anchor matter).
WIDE = dict(sensing_error=True, sense_sensed_pos_m=2.0, sense_sensed_speed_mps=1.0, sense_connected_pos_m=1.0,
            sense_connected_speed_mps=0.5)  # fmt: skip


def _mixed(n_leaders, decel, per_variant=40, seed=0, variants=PAPER_VARIANTS):
    return concat([paper_scenarios(v, n_leaders, decel, per_variant, np.random.default_rng(100 * seed + k), MIXED_F,
                                   first_id=1000 * k) for k, v in enumerate(variants)])  # fmt: skip


def _clear(monkeypatch):
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)


def compiled_and_numpy(monkeypatch, batch, **kwargs):
    """``(the compiled loop's result, the NumPy path's table)`` of ``simulate_batch(batch, seed=4, **kwargs)``: the
    loop asserted to have run, the NumPy path the one source's array functions (``SAFELANE_NO_NUMBA=1``)."""
    _clear(monkeypatch)
    fused = simulate_batch(batch, seed=4, **kwargs)
    assert fused.engine == "compiled loop", fused.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    return fused, simulate_batch(batch, seed=4, **kwargs).table


def _two_paths(monkeypatch, batch, **kwargs):
    """``(compiled loop, period by period)`` tables."""
    _clear(monkeypatch)
    fused = simulate_batch(batch, seed=4, **kwargs)
    assert fused.engine == "compiled loop", fused.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, **kwargs)
    assert periods.engine == "period by period"
    return fused.table, periods.table


def _preset(**update) -> SimConfig:
    """The realistic preset's config with ``update`` (``shield_*`` keys: its shield's)."""
    shield = {k.removeprefix("shield_"): update.pop(k) for k in list(update) if k.startswith("shield_")}
    cfg = PRESET.sim.model_copy(update=update)
    return cfg.model_copy(update=dict(shield=cfg.shield.model_copy(update=shield))) if shield else cfg


#: name: (batch, simulate_batch's arguments, the features on: "sensing" (the shield's box and anchor), "delay" (the
#: shield's delay, the world's), "own" (L0 near), "breach" (L(N+1) brakes beyond a_o_d: the monitor flags breaches)).
CASES = {
    "the realistic preset, N = 3": (
        lambda: _mixed(3, 10.0, seed=0),
        dict(params=REALISTIC, config=PRESET.sim, nominal=PRESET.expert()),
        ("sensing", "delay", "breach"),
    ),
    "the realistic preset with L0 near and wide bounds, N = 2": (
        lambda: _mixed(2, 10.0, seed=1),
        dict(params=REALISTIC, config=_preset(**NEAR_L0, **WIDE), nominal=PRESET.expert()),
        ("sensing", "delay", "own", "breach"),
    ),
    "the shield's sensing without a delay, edge share, no own lane, N = 4": (
        lambda: _mixed(4, 6.0, seed=2),
        dict(params=REALISTIC, config=_preset(**WIDE, own_lane=False, actuation_delay_s=0.0, sensing_edge_share=0.5)),
        ("sensing",),
    ),
    "the shield's sensing, L0 near that the shield ignores, N = 3": (
        lambda: _mixed(3, 6.0, seed=3),
        dict(params=REALISTIC, config=_preset(**NEAR_L0, **WIDE, actuation_delay_s=0.0, shield_own_lane=False)),
        ("sensing",),
    ),
    "a delay of 1 period without sensing, N = 1, a_N+1 = 9 (the paper's vehicles)": (
        lambda: _mixed(1, 9.0, seed=4),
        dict(config=SimConfig(actuation_delay_s=0.1)),
        ("delay",),
    ),
    "a delay of 3 periods, the shield's sensing, L0 near, N = 2": (
        lambda: _mixed(2, 10.0, seed=5),
        dict(params=REALISTIC, config=_preset(**NEAR_L0, actuation_delay_s=0.3)),
        ("sensing", "delay", "own", "breach"),
    ),
    "RSS rows and No_agg_assess, the realistic preset, N = 3": (
        lambda: _mixed(3, 10.0, seed=6, variants=RSS_VARIANTS),
        dict(params=REALISTIC, config=_preset(**WIDE), nominal=PRESET.expert()),
        ("sensing", "delay", "breach"),
    ),
    "the observed assessment, the paper's completion rule, delay 2 periods, N = 1": (
        lambda: _mixed(1, 6.0, seed=7),
        dict(params=REALISTIC, config=_preset(**WIDE, shield_assessment="observed", shield_completion="paper_evasion")),
        ("sensing", "delay"),
    ),
}

#: The table's columns a feature changes (outcomes, counts, the monitor's record).
OUTCOMES = ["n_proceed", "n_hesitate", "n_abort", "min_gap_follower_m", "completion_time_s", "collision",
            "safety_violation", "assumption_breach", "breach_time_s"]  # fmt: skip


def _changed(a, b, cols=OUTCOMES) -> int:
    return int((~(a[cols].fillna(-1.0).to_numpy() == b[cols].fillna(-1.0).to_numpy()).all(1)).sum())


@pytest.mark.parametrize("case", list(CASES))
def test_the_compiled_loop_runs_the_shields_sensing_and_delay_with_the_period_by_period_table(monkeypatch, case):
    make, kwargs, features = CASES[case]
    batch = make()
    fused, periods = _two_paths(monkeypatch, batch, **kwargs)
    assert fused.equals(periods), case
    assert (periods[["n_proceed", "n_hesitate", "n_abort"]].sum() > 0).all()
    assert periods["n_abort"].sum() > 0  # aborts (with commands in flight under a delay)
    cfg = kwargs["config"]
    off = {}
    if "sensing" in features:
        off["shield"] = cfg.shield.model_copy(update=dict(sensing=False))
    if "breach" in features:
        assert 0 < periods["assumption_breach"].sum() < len(batch)
    if "delay" in features:
        shield = off.get("shield", cfg.shield)
        off["shield"] = shield.model_copy(update=dict(actuation_delay_s=0.0))
    if "own" in features:
        gap = periods["min_gap_own_lane_m"]
        assert (gap < 2 * REALISTIC.p_m).sum() > 5, gap.describe()
    # the shield's features change the outcome: without them (the world as it is) the table differs
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    without = simulate_batch(batch, seed=4, **{**kwargs, "config": cfg.model_copy(update=off)}).table
    assert _changed(without, periods) > len(batch) // 20, _changed(without, periods)


def test_the_monitors_anchor_breaches_in_some_rows(monkeypatch):
    """The cumulative comparison with the held anchor flags breaches the period's comparison alone does not (the
    NumPy path with ``monitor.anchor_flags`` off differs), and the compiled loop gives the NumPy path's table."""
    from safelane.shield import monitor

    batch = _mixed(3, 10.0, per_variant=25, seed=8)
    kwargs = dict(params=REALISTIC, config=_preset(**NEAR_L0, **WIDE), nominal=PRESET.expert())
    fused, numpy_table = compiled_and_numpy(monkeypatch, batch, **kwargs)
    assert fused.table.equals(numpy_table)
    monkeypatch.setattr(monitor, "anchor_flags", lambda anchor, active, *a, **k: np.zeros((len(active), 5), bool))
    no_anchor = simulate_batch(batch, seed=4, **kwargs).table
    assert no_anchor["assumption_breach"].sum() < numpy_table["assumption_breach"].sum(), (
        no_anchor["assumption_breach"].sum(), numpy_table["assumption_breach"].sum())  # fmt: skip


def test_the_compiled_period_stepped_from_python_runs_the_shields_sensing_and_delay(monkeypatch):
    """A nominal planner the loop does not run (a subclass of the expert) steps the compiled period from Python
    (``sim/_stepper.Stepper``, engine ``"compiled period"``, its final view ``finish_kernel``): the realistic preset's
    table period by period. The envs' step runs it too (``tests/test_env_realworld.py`` compares it with the NumPy
    env)."""
    mine = type("Mine", (ExpertPlanner,), {})(**PRESET.planner)
    kwargs = dict(params=REALISTIC, nominal=mine, config=_preset(**NEAR_L0, **WIDE))
    batch = _mixed(3, 10.0, per_variant=20, seed=9)
    _clear(monkeypatch)
    stepped = simulate_batch(batch, seed=4, **kwargs)
    assert stepped.engine == "compiled period", (stepped.engine, stepped.engine_reasons)
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, **kwargs)
    assert periods.engine == "period by period"
    assert stepped.table.equals(periods.table)
    assert periods.table["assumption_breach"].any() and periods.table["n_abort"].sum() > 0
    monkeypatch.delenv("SAFELANE_NO_FUSED")
    assert steps_compiled(batch, kwargs["config"], None) == []


def test_the_realistic_preset_runs_in_the_compiled_loop(monkeypatch):
    _clear(monkeypatch)
    batch = _mixed(3, 5.0, per_variant=20)
    assert _fused.reasons(batch, PRESET.sim, PRESET.expert(), None, False, False) == []
    assert simulate_batch(batch, seed=1, params=REALISTIC, config=PRESET.sim,
                          nominal=PRESET.expert()).engine == "compiled loop"  # fmt: skip


@pytest.mark.parametrize(("world", "shield"), [(0.2, 0.1), (0.1, 0.2), (0.0, 0.1)])
def test_a_shields_delay_other_than_the_worlds_runs_period_by_period_and_says_why(monkeypatch, world, shield):
    _clear(monkeypatch)
    cfg = SimConfig(actuation_delay_s=world, shield={"actuation_delay_s": shield})
    why = _fused.reasons(_mixed(1, 5.0, per_variant=20), cfg, ExpertPlanner(), None, False, False)
    assert any(r.startswith(f"config.shield.actuation_delay_s={shield}") for r in why), why
    same = SimConfig(actuation_delay_s=world, shield={"actuation_delay_s": world})
    assert _fused.reasons(_mixed(1, 5.0, per_variant=20), same, ExpertPlanner(), None, False, False) == []


def test_progress_chunks_without_l0_give_the_whole_batchs_table_with_the_shields_sensing(monkeypatch):
    """A run behind a progress bar runs in chunks (``_fused.PROGRESS_CHUNK``), and whether the shield's sensing box
    analyses the own lane (``_fused.kernel_inputs``' ``own_analysed``, ``stages.own_leader``'s batch-wide
    ``Situation.has_own_lane``) is decided per chunk: a chunk whose rows have no ``L0`` runs with it off, the whole
    batch with it on. It reaches only the monitor's anchor for the rows without ``L0`` (whose own columns no
    comparison reads), so the table is the same: chunked, whole and period by period."""
    from dataclasses import replace

    from safelane.sim._fast_loop import PRM
    from safelane.sim.realworld import with_own_lane

    cfg = _preset(**NEAR_L0, **WIDE, l0_decel_mps2=11.0)  # L0 brakes beyond a_o_d: the own lane's anchor flags it
    batch = with_own_lane(_mixed(3, 10.0, per_variant=30, seed=14), 4, cfg, REALISTIC)
    l0_x = batch.l0_x.copy()
    l0_x[:45] = np.inf  # the first chunk of three (40 rows each) has no L0
    batch = replace(batch, l0_x=l0_x)
    kwargs = dict(params=REALISTIC, config=cfg, nominal=PRESET.expert())
    analysed = []
    real = _fused.kernel_inputs
    monkeypatch.setattr(_fused, "kernel_inputs", lambda sim, **k: analysed.append(real(sim, **k)[0][
        PRM.index("own_analysed")]) or real(sim, **k))  # fmt: skip
    monkeypatch.setattr(_fused, "PROGRESS_CHUNK", 40)
    _clear(monkeypatch)
    chunked = simulate_batch(batch, seed=4, progress=True, **kwargs)
    assert chunked.engine == "compiled loop", chunked.engine_reasons
    assert analysed == [0.0, 1.0, 1.0]
    whole = simulate_batch(batch, seed=4, **kwargs)
    assert analysed[3:] == [1.0]
    assert chunked.table.equals(whole.table)
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    assert simulate_batch(batch, seed=4, **kwargs).table.equals(whole.table)
    table = whole.table
    assert np.isnan(table["min_gap_own_lane_m"].to_numpy()[:45]).all()
    assert 0 < table["assumption_breach"].sum() < len(batch) and table["assumption_breach"].to_numpy()[45:].any()
