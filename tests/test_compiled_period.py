"""Simulations that the whole-episode compiled loop does not take only because of their nominal planner, a trace or
recorded observations run their periods compiled (``sim/_stepper.Stepper``: ``engine == "compiled period"``), the
planner between periods: the table, the trace and the observations are the NumPy path's (``SAFELANE_NO_FUSED=1``),
bit for bit, and the table is the compiled loop's where that loop runs too."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("numba", reason="the compiled period needs the fast extra")

from safelane.planners.adversarial import Oscillating, RecklessMerge
from safelane.planners.base import ExpertPlanner
from safelane.sim import paper_scenarios, simulate_batch


def batch(rows: int = 96, seed: int = 4):
    parts = [paper_scenarios(v, n, d, rows // 4, np.random.default_rng(seed + i))
             for i, (v, n, d) in enumerate([("CV_all", 3, 6.0), ("CV_none", 1, 4.0), ("CV_follow", 3, 8.0),
                                            ("No_agg_assess", 0, 5.0)])]  # fmt: skip
    from safelane.sim import concat

    return concat(parts)


def both(monkeypatch, b, **kw):
    compiled = simulate_batch(b, seed=2, **kw)
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    reference = simulate_batch(b, seed=2, **kw)
    monkeypatch.delenv("SAFELANE_NO_FUSED")
    assert reference.engine == "period by period"
    return compiled, reference


def test_a_trace_runs_compiled_periods_with_the_numpy_paths_trace_and_the_loops_table(monkeypatch):
    b = batch()
    compiled, reference = both(monkeypatch, b, trace=True, trace_limit=40)
    assert compiled.engine == "compiled period", compiled.engine_reasons
    pd.testing.assert_frame_equal(compiled.trace, reference.trace)
    pd.testing.assert_frame_equal(compiled.table, reference.table)
    loop = simulate_batch(b, seed=2)
    assert loop.engine == "compiled loop"
    pd.testing.assert_frame_equal(compiled.table, loop.table)
    assert compiled.trace["behaviour"].isin([1, 2]).any()  # the shield acted in the traced rows


@dataclasses.dataclass(frozen=True)
class UsersPlanner:
    """A planner of the user's own (here the oscillating adversary behind a class the loop does not know)."""

    inner: object = Oscillating()

    def __call__(self, obs, params):
        return self.inner(obs, params)


@pytest.mark.parametrize("nominal", [UsersPlanner(), UsersPlanner(RecklessMerge()), Oscillating(), RecklessMerge(),
                                     ExpertPlanner(k_p=0.5)], ids=type)  # fmt: skip
def test_any_nominal_planner_runs_compiled_periods_with_the_numpy_paths_table(monkeypatch, nominal):
    compiled, reference = both(monkeypatch, batch(), nominal=nominal)
    # the expert and the adversaries (as data) run in the whole-episode loop, any other planner between periods
    assert compiled.engine == ("compiled period" if type(nominal) is UsersPlanner else "compiled loop")
    pd.testing.assert_frame_equal(compiled.table, reference.table)
    assert (compiled.table["n_hesitate"] + compiled.table["n_abort"]).sum() > 0


def test_recorded_observations_are_the_numpy_paths(monkeypatch):
    compiled, reference = both(monkeypatch, batch(32), record_observations=True)
    assert compiled.engine == "compiled period"
    assert len(compiled.observations) == len(reference.observations) > 0
    for a, r in zip(compiled.observations, reference.observations, strict=True):
        for field in dataclasses.fields(a):
            x, y = getattr(a, field.name), getattr(r, field.name)
            assert np.array_equal(x, y), field.name
        assert isinstance(a.t, float)  # one clock, as the NumPy path's


def test_blame_and_settings_outside_the_compiled_period_stay_period_by_period():
    b = batch(32)
    assert simulate_batch(b, seed=2, trace=True, blame=True).engine == "period by period"
    from safelane.sim import SimConfig

    noisy = simulate_batch(b, seed=2, trace=True, config=SimConfig(sensor_noise_std=0.1))
    assert noisy.engine == "period by period"
    assert any("sensor_noise_std" in r for r in noisy.engine_reasons)
