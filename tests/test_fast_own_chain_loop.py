"""The own lane as a chain (``sim/own_chain.py``: ``L0`` and connected vehicles ahead of it, the non-connected head
driving the profile) in the compiled closed loop (``sim/_fast_world.own_lane_motion``, ``own_pairs``) against the
loop period by period (``SAFELANE_NO_FUSED=1``) and the NumPy path (``SAFELANE_NO_NUMBA=1``): the same per-scenario
table, column for column and bit for bit — chains of one to three connected vehicles drawn by the config
(``realworld._with_own_chain``) and the falsifier's (``falsify_build``: chains of 0–3 per row, rows without ``L0``, the
heads' profiles switching inside a period, the adversarial planners and the traffic hooks), with the shield's sensing
box and delay on and off and the shield blind to the own lane, stepped from Python too (``Stepper``) — each on a batch
where the chain changes the outcome, so that the comparison can fail; and a chain whose vehicles start inside each
other, so that the pairs' check (``own_lane_leader_collision``) can fail too."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane.planners.base import ExpertPlanner
from safelane.sim import ScenarioConfig, _fused, concat, paper_scenarios, simulate_batch
from safelane.sim._stepper import steps_compiled
from safelane.sim.preset import load_preset
from safelane.sim.realworld import with_own_lane
from test_fast_core import needs_numba
from test_fast_realistic_loop import compiled_and_numpy

pytestmark = [pytest.mark.compiled, needs_numba, pytest.mark.filterwarnings("ignore:a_x_N\\+1_d")]

PRESET = load_preset("realistic")
REALISTIC = PRESET.params
VARIANTS = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
#: The chain near the ego and braking early (its own instants and the head's within 2 s).
NEAR = dict(own_lane=True, l0_gap_min_m=6.0, l0_gap_max_m=30.0, l0_brake_window_s=2.0)


def _mixed(n_leaders, decel, per_variant=40, seed=0):
    mixed_f = ScenarioConfig(follower_connected_share=0.5)
    return concat([paper_scenarios(v, n_leaders, decel, per_variant, np.random.default_rng(100 * seed + k), mixed_f,
                                   first_id=1000 * k) for k, v in enumerate(VARIANTS)])  # fmt: skip


def _preset(**update):
    """The realistic preset's config with ``update`` (``shield_*`` keys: its shield's)."""
    shield = {k.removeprefix("shield_"): update.pop(k) for k in list(update) if k.startswith("shield_")}
    cfg = PRESET.sim.model_copy(update=update)
    return cfg.model_copy(update=dict(shield=cfg.shield.model_copy(update=shield))) if shield else cfg


def _clear(monkeypatch):
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)


def _alone(batch):
    """``batch`` with its own lane's chain dropped: ``L0`` alone, driving the head's profile."""
    return dataclasses.replace(batch, own_ahead_x=None, own_ahead_v=None, own_promise=None, own_n_connected=None,
                               own_brake_t=None)  # fmt: skip


def _overlapping(batch, every=3):
    """``batch`` (a chain) with every ``every``-th row's first vehicle ahead of ``L0`` 1 m ahead of it: inside it."""
    ahead = batch.own_ahead_x.copy()
    ahead[::every, 0] = batch.l0_x[::every] + 1.0
    return dataclasses.replace(batch, own_ahead_x=ahead)


#: name: (the batch with its chain, simulate_batch's arguments, the chain's vehicles can collide with each other).
CASES = {
    "two connected, the realistic preset (the shield's sensing box and delay on), N = 3": (
        lambda: with_own_lane(_mixed(3, 8.0), 4, _preset(**NEAR, own_lane_connected=2), REALISTIC),
        dict(params=REALISTIC, config=_preset(**NEAR, own_lane_connected=2), nominal=PRESET.expert()),
        False,
    ),
    "three connected, sensing error with the edge share (the shield's sensing off), no delay, N = 2": (
        lambda: with_own_lane(_mixed(2, 7.0, seed=1), 4, _preset(**NEAR, own_lane_connected=3), REALISTIC),
        dict(params=REALISTIC, config=_preset(**NEAR, own_lane_connected=3, sensing_edge_share=0.5,
                                              actuation_delay_s=0.0, shield_sensing=False,
                                              shield_actuation_delay_s=0.0)),
        False,
    ),
    "one connected, the shield blind to the own lane, N = 3": (
        lambda: with_own_lane(_mixed(3, 6.0, seed=2), 4, _preset(**NEAR, own_lane_connected=1), REALISTIC),
        dict(params=REALISTIC, config=_preset(**NEAR, own_lane_connected=1, shield_own_lane=False)),
        False,
    ),
    "two connected, every third row's vehicles inside each other, N = 1": (
        lambda: _overlapping(with_own_lane(_mixed(1, 6.0, seed=3), 4, _preset(**NEAR, own_lane_connected=2),
                                           REALISTIC)),
        dict(params=REALISTIC, config=_preset(**NEAR, own_lane_connected=2), nominal=PRESET.expert()),
        True,
    ),
}

#: The table's columns the chain changes (outcomes, counts, the smallest gaps).
OUTCOMES = ["n_proceed", "n_hesitate", "n_abort", "min_gap_follower_m", "min_gap_own_lane_m", "completion_time_s",
            "collision", "safety_violation", "assumption_breach"]  # fmt: skip


def _changed(a, b) -> int:
    return int((~(a[OUTCOMES].fillna(-1.0).to_numpy() == b[OUTCOMES].fillna(-1.0).to_numpy()).all(1)).sum())


@pytest.mark.parametrize("case", list(CASES))
def test_the_compiled_loop_runs_an_own_lane_chain_with_the_period_by_period_table(monkeypatch, case):
    make, kwargs, overlapping = CASES[case]
    batch = make()
    assert batch.own_ahead_x.shape[1] >= 1 and (batch.own_n_connected >= 1).all()
    _clear(monkeypatch)
    calls = []
    real = _fused.run_chunk
    monkeypatch.setattr(_fused, "run_chunk", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(_fused, "PROGRESS_CHUNK", 100)  # chunks: the own lane's final states concatenated
    fused = simulate_batch(batch, seed=4, progress=True, **kwargs)
    assert fused.engine == "compiled loop", fused.engine_reasons
    assert len(calls) == 2
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, **kwargs)
    assert periods.engine == "period by period"
    assert fused.table.equals(periods.table), case
    table = periods.table
    assert (table["min_gap_own_lane_m"] < 2 * REALISTIC.p_m).sum() > 5
    assert table["own_lane_leader_collision"].any() == overlapping
    if overlapping:
        assert table["own_lane_leader_collision"].sum() < len(batch)
    # the chain changes the outcome (L0 connected: its worst case, and so the shield's choices): without it the
    # table differs
    without = simulate_batch(_alone(batch), seed=4, **kwargs).table
    assert _changed(without, table) > len(batch) // 10, _changed(without, table)


def test_the_numpy_path_gives_the_same_table_with_a_chain(monkeypatch):
    """The compiled loop against the NumPy path itself (``SAFELANE_NO_NUMBA=1``: the array functions, the one
    source's other evaluation) on a smaller batch, the chain's vehicles inside each other in some rows."""
    cfg = _preset(**NEAR, own_lane_connected=3, sensing_edge_share=0.3)
    batch = _overlapping(with_own_lane(_mixed(2, 8.0, per_variant=20, seed=5), 4, cfg, REALISTIC), every=4)
    kwargs = dict(params=REALISTIC, config=cfg, nominal=PRESET.expert())
    fused, reference = compiled_and_numpy(monkeypatch, batch, **kwargs)
    assert fused.table.equals(reference)
    assert reference["own_lane_leader_collision"].any() and (reference["min_gap_own_lane_m"] < REALISTIC.p_m).any()


def test_the_compiled_period_stepped_from_python_runs_a_chain(monkeypatch):
    """A nominal planner the loop does not run (a subclass of the expert) steps the compiled period from Python
    (``Stepper``, engine ``"compiled period"``, its final view ``finish_kernel``): the period-by-period table."""
    mine = type("Mine", (ExpertPlanner,), {})(**PRESET.planner)
    cfg = _preset(**NEAR, own_lane_connected=2)
    batch = _overlapping(with_own_lane(_mixed(3, 8.0, per_variant=20, seed=6), 4, cfg, REALISTIC))
    kwargs = dict(params=REALISTIC, nominal=mine, config=cfg)
    _clear(monkeypatch)
    stepped = simulate_batch(batch, seed=4, **kwargs)
    assert stepped.engine == "compiled period", (stepped.engine, stepped.engine_reasons)
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, **kwargs)
    assert stepped.table.equals(periods.table)
    assert periods.table["own_lane_leader_collision"].any()
    monkeypatch.delenv("SAFELANE_NO_FUSED")
    assert steps_compiled(batch, cfg, None) == []


def test_the_falsifiers_realistic_batches_run_compiled_with_the_period_by_period_outcomes(monkeypatch):
    """The falsifier's realistic world (``Setting.realistic``): specs whose own lanes hold 0–3 connected vehicles
    (``falsify_build._own_chain``), ``L0`` absent in some rows, the heads' profiles switching inside a period, the
    adversarial planners and the traffic hooks as data, the delay from the spec — simulated in the compiled loop
    (every group of a round) and period by period: the same outcomes, row for row."""
    from safelane.experiments import falsify as fz
    from safelane.experiments import falsify_space as space

    setting = fz.Setting.realistic()
    prm = setting.params
    dim = space.dimension(prm, "realistic")
    rng = np.random.default_rng(11)
    specs = [space.decode(rng.uniform(size=(600, dim)), prm, 0.0, "realistic"),
             space.knife_specs(rng, 600, prm, 0.0, "realistic")]  # fmt: skip
    spec = space.concat_specs(specs)
    assert (spec["own_n"] == 0).any() and (spec["own_n"] == 3).any() and (~spec["l0_present"]).any()
    _clear(monkeypatch)
    asked = []  # what the dispatch answered for each simulation of the round (its groups: start time, delay)
    real = _fused.reasons
    monkeypatch.setattr(_fused, "reasons", lambda *a, **k: asked.append(real(*a, **k)) or asked[-1])
    fused, _ = fz.evaluate(spec, setting)
    assert len(asked) > 1 and all(why == [] for why in asked), asked
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods, _ = fz.evaluate(spec, setting)
    assert len(fused) > 200 and fused.equals(periods)
    chained = np.flatnonzero(spec["own_n"][fused["row"].to_numpy()] > 0)
    assert chained.size > 50
    assert not fused[list(fz.OUTCOMES)].to_numpy().any()  # inside the assumptions: no collision, no violation


def test_a_chain_runs_compiled_in_the_dispatch(monkeypatch):
    """No refusal names the chain any more: the config's (``own_lane_connected``) and a batch's own
    (``ScenarioBatch.own_ahead_x``, the falsifier's), in the loop and stepped."""
    _clear(monkeypatch)
    cfg = _preset(own_lane_connected=2)
    chained = with_own_lane(_mixed(1, 5.0, per_variant=20), 4, cfg, REALISTIC)
    assert chained.own_ahead_x is not None
    assert _fused.reasons(chained, cfg, ExpertPlanner(), None, False, False) == []
    assert _fused.reasons(chained, PRESET.sim, ExpertPlanner(), None, False, False) == []
    assert steps_compiled(chained, cfg, None) == []
