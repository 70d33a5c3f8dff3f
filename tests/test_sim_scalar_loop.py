"""The batched engine against an independent per-scenario re-implementation on the scalar safety API.

``scalar_loop.loop_scenario`` runs one scenario in Python floats (the baseline of ``benchmarks/bench_sim.py``).
Both must make the same decisions: the same proceed / hesitate / abort count in every scenario, the same
completion time, the same outcome.
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.planners.variants import PAPER_VARIANT_NAMES as VARIANT_NAMES  # the RSS baselines: test_rss.py
from safelane.sim import SimConfig, simulate_batch
from scalar_loop import loop_scenario
from scalar_loop_reference import reference_loop
from sim_scenarios import mixed_campaign_batch

PARAMS = Params()
#: Periods of the reference loop: every lane change of these scenarios is decided (completed or abandoned) by then;
#: the reference costs ~0.3 CPU s per period (one batched reference call per round of requests).
STEPS_REFERENCE = 60


@pytest.mark.parametrize("planner", VARIANT_NAMES)
def test_engine_and_scalar_loop_make_the_same_decisions(planner):
    batch = mixed_campaign_batch(planner, 15, np.random.default_rng(VARIANT_NAMES.index(planner)))
    table = simulate_batch(batch).table
    for i in range(len(batch)):
        row = loop_scenario(batch, i, PARAMS, steps=100)
        assert row["counts"] == table.loc[i, ["n_proceed", "n_hesitate", "n_abort"]].tolist(), i
        assert row["completion_time_s"] == pytest.approx(table.loc[i, "completion_time_s"], abs=1e-9, nan_ok=True)
        for col in ("success", "collision", "safety_violation", "leader_collision"):
            assert row[col] == table.loc[i, col], (i, col)
    assert table["n_abort"].sum() > 0 and table["n_hesitate"].sum() > 0


def test_engine_and_the_reference_loop_make_the_same_decisions():
    """The same loop with every piece of safety maths answered by the independent numeric reference
    (``scalar_loop_reference``: time stepping and bisection, no closed form of the library), the four variants in
    lockstep: the engine must make the same decisions, to the documented tolerances."""
    scenarios, tables = [], []
    for k, planner in enumerate(VARIANT_NAMES):
        batch = mixed_campaign_batch(planner, 5, np.random.default_rng(100 + k))
        tables.append(simulate_batch(batch, config=SimConfig(horizon_s=STEPS_REFERENCE * PARAMS.dt)).table)
        scenarios += [(batch, i) for i in range(len(batch))]
    rows = reference_loop(scenarios, PARAMS, steps=STEPS_REFERENCE)
    it = iter(rows)
    for table in tables:
        for i in range(len(table)):
            row = next(it)
            assert row["counts"] == table.loc[i, ["n_proceed", "n_hesitate", "n_abort"]].tolist(), i
            assert row["completion_time_s"] == pytest.approx(table.loc[i, "completion_time_s"], abs=1e-6, nan_ok=True)
            for col in ("success", "collision", "safety_violation", "leader_collision"):
                assert row[col] == table.loc[i, col], (i, col)
    assert sum(r["counts"][2] for r in rows) > 0 and sum(r["counts"][1] for r in rows) > 0
