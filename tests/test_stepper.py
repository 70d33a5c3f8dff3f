"""``Stepper.advance`` (the compiled period with the rows advanced in place, as ``simulate_batch`` steps them) gives
what ``Stepper.step`` (the state a value) gives: the results table, every period's behaviour codes and every
observation, bit for bit — also the observations a planner keeps from earlier periods — on a batch with mixed
outcomes; and ``step`` still leaves the state it is given as it was."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("numba", reason="the compiled period needs the fast extra")

from safelane.planners.registry import load_nominal
from safelane.sim import concat, paper_scenarios
from safelane.sim._stepper import Stepper
from safelane.sim.preset import load_preset
from safelane.sim.results import results_table
from safelane.sim.step import ClosedLoop


def mixed_batch():
    """Cells from an easy one (every lane change completes) to hopeless ones, every variant."""
    parts = [paper_scenarios(v, n, d, 12, np.random.default_rng(7 + i))
             for i, (v, n, d) in enumerate([("CV_all", 3, 2.0), ("CV_none", 1, 4.0), ("CV_follow", 3, 5.0),
                                            ("No_agg_assess", 1, 6.0), ("CV_all", 10, 5.0)])]  # fmt: skip
    return concat(parts)


@dataclasses.dataclass
class Remembering:
    """The paper's network, keeping every observation it is shown (as a planner with a memory would)."""

    inner: object
    seen: list = dataclasses.field(default_factory=list)
    __name__ = "remembering"

    def __call__(self, obs, params):
        self.seen.append(obs)
        return self.inner(obs, params)


def run(way: str):
    preset = load_preset("paper")
    planner = Remembering(load_nominal("mlp_paper"))
    b = mixed_batch()
    sim = Stepper(ClosedLoop(b, 3, preset.params, preset.sim, planner), shared_clock=True)
    state, observations, behaviours = sim.initial_state(), [], []
    for _ in range(round(preset.sim.horizon_s / preset.params.dt)):
        state, obs, behaviour = (sim.step if way == "step" else sim.advance)(state)
        observations.append(obs)
        behaviours.append(behaviour)
    return results_table(b, sim.finish(state)), observations, behaviours, planner.seen


def test_advance_gives_steps_table_behaviours_and_observations():
    table, observations, behaviours, seen = run("step")
    table_now, observations_now, behaviours_now, seen_now = run("advance")
    pd.testing.assert_frame_equal(table_now, table, check_exact=True)
    outcomes = table["success"].to_numpy()
    assert outcomes.any() and not outcomes.all()  # mixed outcomes
    assert (table["n_hesitate"] + table["n_abort"]).sum() > 0  # the shield acted
    assert len(observations_now) == len(observations) == len(behaviours_now) > 0
    for now, before in zip(behaviours_now, behaviours, strict=True):
        np.testing.assert_array_equal(now, before)
    for kept in ((observations_now, observations), (seen_now, seen)):  # read after the run: none changed since
        for now, before in zip(*kept, strict=True):
            for field in dataclasses.fields(before):
                x, y = getattr(now, field.name), getattr(before, field.name)
                assert np.array_equal(x, y) and np.asarray(x).dtype == np.asarray(y).dtype, field.name


def test_step_leaves_its_state_and_advance_advances_it_in_place():
    preset = load_preset("paper")
    sim = Stepper(ClosedLoop(mixed_batch(), 3, preset.params, preset.sim, load_nominal("mlp_paper")))
    start = sim.initial_state()
    before = [a.copy() for a in start.rows]
    after, _, _ = sim.step(start)
    for a, b in zip(start.rows, before, strict=True):
        np.testing.assert_array_equal(a, b)
    same, obs, _ = sim.advance(start)
    assert same is start
    for a, b in zip(start.rows, after.rows, strict=True):
        np.testing.assert_array_equal(a, b)
    for field in dataclasses.fields(obs):  # the observation is its own
        value = getattr(obs, field.name)
        if isinstance(value, np.ndarray):
            assert not any(np.may_share_memory(value, a) for a in start.rows), field.name
