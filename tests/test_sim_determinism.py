"""Determinism and batch/single parity of the simulator (issue 3, item 4).

Per-step randomness (unexpected promise violations, sensor noise) is counter-based — keyed by (seed, scenario
id, step, slot) — so a scenario's row does not depend on the batch it runs in: not on its neighbours, not on
its position, not on how far the vehicle axis is padded.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from safelane.sim import SimConfig, simulate, simulate_batch
from safelane.sim.rng import counter_normal, counter_uniform
from sim_scenarios import mixed_campaign_batch

NOISY = SimConfig(sensor_noise_std=0.1)


def _row(table: pd.DataFrame, i: int) -> pd.DataFrame:
    return table.iloc[[i]].reset_index(drop=True)


def test_same_seed_same_table():
    kwargs = dict(n_leaders=3, decel=5.0, samples=30, p_v=0.1, config=NOISY)
    first = simulate("CV_all", seed=7, **kwargs).table
    again = simulate("CV_all", seed=7, **kwargs).table
    pd.testing.assert_frame_equal(first, again)
    other = simulate("CV_all", seed=8, **kwargs).table
    assert not first.equals(other)


def test_same_seed_same_trace():
    kwargs = dict(n_leaders=1, decel=4.0, samples=5, seed=2, trace=True, config=SimConfig(horizon_s=4.0))
    pd.testing.assert_frame_equal(simulate("CV_none", **kwargs).trace, simulate("CV_none", **kwargs).trace)


@pytest.fixture(scope="module")
def noisy_batch():
    """A mixed batch (N from 0 to 10, so the vehicle axis is padded for most rows) with unexpected promise
    violations and sensor noise, and its table."""
    batch = mixed_campaign_batch("CV_all", 40, np.random.default_rng(9), p_v=0.2)
    return batch, simulate_batch(batch, seed=3, config=NOISY).table


def test_randomness_really_acts_in_the_parity_batch(noisy_batch):
    batch, table = noisy_batch
    calm = simulate_batch(dataclasses.replace(batch, p_v=np.zeros(len(batch))), seed=3, config=SimConfig()).table
    # The unexpected violations act: the monitor sees leaders beyond their bounds (and, on, keeps the ego safe).
    assert (table["breach_leader_bound"] != calm["breach_leader_bound"]).any()
    assert (table["assessment_time_s"].fillna(-1) != calm["assessment_time_s"].fillna(-1)).any()


@pytest.mark.parametrize("i", [0, 9, 17, 25, 39])
def test_one_scenario_alone_equals_its_row_in_the_batch(noisy_batch, i):
    batch, table = noisy_batch
    alone = simulate_batch(batch.take([i]), seed=3, config=NOISY).table
    pd.testing.assert_frame_equal(alone, _row(table, i))


@pytest.mark.parametrize("i", [0, 9, 25])
def test_unpadded_scenario_equals_its_padded_row(noisy_batch, i):
    # The same scenario without the padding vehicles its batch-mates forced on it.
    batch, table = noisy_batch
    row = batch.take([i])
    k = int(row.n_connected[0]) + 2
    trimmed = dataclasses.replace(
        row,
        **{
            f.name: getattr(row, f.name)[:, :k]
            for f in dataclasses.fields(row)
            if getattr(row, f.name) is not None and getattr(row, f.name).ndim == 2
        },
    )
    assert trimmed.x.shape[1] < batch.x.shape[1]
    pd.testing.assert_frame_equal(simulate_batch(trimmed, seed=3, config=NOISY).table, _row(table, i))


def test_reversed_batch_gives_reversed_table(noisy_batch):
    batch, table = noisy_batch
    order = np.arange(len(batch))[::-1]
    flipped = simulate_batch(batch.take(order), seed=3, config=NOISY).table
    pd.testing.assert_frame_equal(flipped, table.iloc[order].reset_index(drop=True))


def test_workers_split_gives_the_same_table(noisy_batch):
    batch, table = noisy_batch
    rows = np.arange(0, 40, 3)
    split = simulate_batch(batch.take(rows), seed=3, config=NOISY, workers=2).table
    pd.testing.assert_frame_equal(split, table.iloc[rows].reset_index(drop=True))


def test_counter_based_draws_depend_only_on_their_counters():
    ids = np.arange(1000)
    u = counter_uniform(5, ids[:, None], 3, np.arange(4)[None, :], 7)
    assert u.shape == (1000, 4) and (u >= 0).all() and (u < 1).all()
    np.testing.assert_array_equal(u[123], counter_uniform(5, 123, 3, np.arange(4), 7))
    assert abs(u.mean() - 0.5) < 0.02 and abs(u.std() - np.sqrt(1 / 12)) < 0.01
    assert not np.array_equal(u, counter_uniform(6, ids[:, None], 3, np.arange(4)[None, :], 7))
    z = counter_normal(5, ids, 0, 0)
    assert abs(z.mean()) < 0.1 and abs(z.std() - 1.0) < 0.1
    np.testing.assert_array_equal(z[[4, 500]], counter_normal(5, np.array([4, 500]), 0, 0))
