"""The aggressiveness assessment: unit behaviour, and accuracy / time to detection on the scenario distribution.

``benchmarks/assessment_report.py`` prints the same statistics over a larger grid.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from safelane.shield import assessment as assess
from safelane.sim import ScenarioConfig, SimConfig, concat, paper_scenarios, simulate_batch

DT, WINDOW, THRESHOLD = 0.1, 5, 0.2
#: Non-connected followers only, half of them aggressive: every follower must be assessed.
UNCONNECTED = ScenarioConfig(follower_connected_share=0.0, follower_aggressive_share=0.5)


def _run_speeds(speeds: np.ndarray) -> assess.AssessmentState:
    """Feed ``speeds (B, T)`` one period at a time."""
    state = assess.AssessmentState.start(speeds.shape[0], WINDOW)
    for step in range(speeds.shape[1]):
        state = assess.update(state, speeds[:, step], step * DT, DT, THRESHOLD)
    return state


def test_belief_starts_aggressive_and_needs_a_full_window():
    t = np.arange(WINDOW - 1) * DT
    state = _run_speeds(30.0 - 2.0 * t[None, :])  # braking hard, but only WINDOW - 1 observations
    assert state.aggressive.all() and np.isnan(state.first_collaborative_s).all()


def test_yielding_follower_is_collaborative_at_the_first_full_window():
    t = np.arange(20) * DT
    speeds = np.stack([30.0 - 0.5 * t, 30.0 + 0.0 * t, 30.0 - 0.1 * t])  # yields / cruises / barely slows
    state = _run_speeds(speeds)
    assert list(state.aggressive) == [False, True, True]
    assert state.first_collaborative_s[0] == pytest.approx((WINDOW - 1) * DT)


def test_aggressive_evidence_is_latched():
    t = np.arange(30) * DT
    # Speeds up for 1 s (closing the gap), then has to brake behind L1: stays "aggressive".
    closing_then_braking = np.where(t < 1.0, 30.0 + 2.5 * t, 32.5 - 3.0 * (t - 1.0))
    state = _run_speeds(closing_then_braking[None, :])
    assert state.aggressive.all() and state.latched.all() and np.isnan(state.first_collaborative_s).all()
    # A yielding follower that later matches the ego's acceleration becomes "aggressive" for good (safe side).
    yield_then_speed_up = np.where(t < 1.0, 30.0 - 0.5 * t, 29.5 + 0.5 * (t - 1.0))
    state = _run_speeds(yield_then_speed_up[None, :])
    assert state.aggressive.all() and state.first_collaborative_s[0] == pytest.approx(0.4)


def _distribution(noise: float, samples_per_cell: int = 40, seed: int = 0) -> pd.DataFrame:
    """Assessment outcomes on the paper's sampler over N ∈ {0, 1, 5, 10} × a_x_N+1_d ∈ {2, 5, 8} (CV_none, whose
    supervisor uses the assessment)."""
    rng = np.random.default_rng(seed)
    cells = [(n, d) for n in (0, 1, 5, 10) for d in (2.0, 5.0, 8.0)]
    parts = [
        paper_scenarios("CV_none", n, d, samples_per_cell, rng, UNCONNECTED, first_id=i * samples_per_cell)
        for i, (n, d) in enumerate(cells)
    ]
    cfg = SimConfig(assessment="observed", sensor_noise_std=noise)
    return simulate_batch(concat(parts), seed=seed, config=cfg).table


@pytest.fixture(scope="module")
def noiseless():
    return _distribution(0.0)


def test_collaborative_followers_detected_within_a_second(noiseless):
    collab = noiseless[~noiseless["follower_aggressive"]]
    assert len(collab) > 100
    assert collab["assessment_correct"].all()
    assert (collab["assessment_time_s"] <= 1.0).all()


def test_aggressive_followers_never_flagged_collaborative(noiseless):
    aggressive = noiseless[noiseless["follower_aggressive"]]
    assert len(aggressive) > 100
    assert aggressive["assessed_aggressive"].all() and aggressive["assessment_time_s"].isna().all()


def test_sensor_noise_errs_on_the_safe_side():
    table = _distribution(0.1, samples_per_cell=15, seed=1)
    aggressive = table[table["follower_aggressive"]]
    collab = table[~table["follower_aggressive"]]
    assert aggressive["assessed_aggressive"].all()  # never the unsafe mistake
    assert 0.3 < collab["assessment_correct"].mean() < 1.0  # noise costs collaborative detections


def test_truth_mode_still_reports_the_observed_assessment():
    batch = paper_scenarios("CV_none", 1, 4.0, 20, np.random.default_rng(4), UNCONNECTED)
    table = simulate_batch(batch, config=SimConfig(assessment="truth", horizon_s=1.0)).table
    assert (table["assessed_aggressive"] == table["follower_aggressive"]).all()
    assert table["assessment_correct"].all()
