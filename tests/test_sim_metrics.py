"""Rates with 95 % Wilson score intervals, and per-cell summaries of a results table."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from safelane.sim import SimConfig, simulate, summarize, wilson_interval
from safelane.sim.metrics import RATE_COLUMNS, Z95


def _score_test_bounds(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson interval by its definition — the proportions ``p`` not rejected by the score test,
    ``|k/n − p| <= z sqrt(p (1 − p) / n)`` — found by bisection on each side of ``k/n``."""
    phat = k / n

    def accepted(p):
        return abs(phat - p) <= z * np.sqrt(p * (1.0 - p) / n)

    def edge(inside, outside):
        for _ in range(200):
            mid = 0.5 * (inside + outside)
            inside, outside = (mid, outside) if accepted(mid) else (inside, mid)
        return inside

    lo = 0.0 if k == 0 else edge(phat, 0.0)
    hi = 1.0 if k == n else edge(phat, 1.0)
    return lo, hi


_HALF_5_OF_10 = Z95 * np.sqrt(0.025 + Z95**2 / 400) / (1 + Z95**2 / 10)
_CENTRE_1_OF_4 = (0.25 + Z95**2 / 8) / (1 + Z95**2 / 4)
_HALF_1_OF_4 = Z95 * np.sqrt(0.25 * 0.75 / 4 + Z95**2 / 64) / (1 + Z95**2 / 4)


@pytest.mark.parametrize(
    ("k", "n", "expected"),
    [
        # Hand computation: for k = 0 the interval is [0, z²/(n + z²)].
        (0, 10, (0.0, Z95**2 / (10 + Z95**2))),
        (10, 10, (1.0 - Z95**2 / (10 + Z95**2), 1.0)),
        (0, 20_000, (0.0, Z95**2 / (20_000 + Z95**2))),
        # 5 of 10: centre (p + z²/2n)/(1 + z²/n) = 0.5, half-width z sqrt(p(1 − p)/n + z²/4n²) / (1 + z²/n)
        # = z sqrt(0.025 + z²/400) / (1 + z²/10) on both sides.
        (5, 10, (0.5 - _HALF_5_OF_10, 0.5 + _HALF_5_OF_10)),
        # 1 of 4: centre (0.25 + z²/8)/(1 + z²/4), half-width z sqrt(0.25·0.75/4 + z²/64) / (1 + z²/4).
        (1, 4, (_CENTRE_1_OF_4 - _HALF_1_OF_4, _CENTRE_1_OF_4 + _HALF_1_OF_4)),
    ],
)
def test_wilson_interval_hand_computed(k, n, expected):
    lo, hi = wilson_interval(k, n)
    assert (float(lo), float(hi)) == pytest.approx(expected, abs=1e-12)


def test_wilson_zero_of_twenty_thousand_is_below_two_in_ten_thousand():
    _, hi = wilson_interval(0, 20_000)
    assert float(hi) == pytest.approx(1.9204e-4, rel=1e-4)


@pytest.mark.parametrize(("k", "n"), [(0, 1), (1, 1), (3, 7), (17, 200), (999, 1000), (12_345, 20_000)])
def test_wilson_interval_inverts_the_score_test(k, n):
    lo, hi = wilson_interval(k, n)
    ref_lo, ref_hi = _score_test_bounds(k, n)
    assert float(lo) == pytest.approx(ref_lo, abs=1e-12) and float(hi) == pytest.approx(ref_hi, abs=1e-12)


def test_wilson_interval_matches_scipy():
    binomtest = pytest.importorskip("scipy.stats").binomtest
    rng = np.random.default_rng(0)
    n = rng.integers(1, 5000, 50)
    k = rng.integers(0, n + 1)
    lo, hi = wilson_interval(k, n)
    for i in range(len(n)):
        ci = binomtest(int(k[i]), int(n[i])).proportion_ci(method="wilson")
        assert lo[i] == pytest.approx(ci.low, abs=1e-12) and hi[i] == pytest.approx(ci.high, abs=1e-12)


def test_wilson_interval_broadcasts_and_contains_the_rate():
    k = np.array([[0, 1, 2], [3, 4, 5]])
    lo, hi = wilson_interval(k, 5)
    assert lo.shape == hi.shape == (2, 3)
    assert (lo <= k / 5).all() and (k / 5 <= hi).all() and (lo >= 0).all() and (hi <= 1).all()
    narrow = wilson_interval(k * 100, 500)
    assert ((narrow[1] - narrow[0]) < (hi - lo)).all()


@pytest.mark.parametrize(("k", "n", "match"), [(1, 0, "n must be positive"), (-1, 5, r"\[0, n\]"), (6, 5, r"\[0, n\]")])
def test_wilson_interval_rejects_bad_counts(k, n, match):
    with pytest.raises(ValueError, match=match):
        wilson_interval(k, n)


@pytest.fixture(scope="module")
def two_cells():
    short = SimConfig(horizon_s=5.0)
    a = simulate("CV_all", 1, 4.0, 40, seed=1, config=short).table
    b = simulate("No_agg_assess", 1, 4.0, 30, seed=1, config=short).table
    return pd.concat([a, b], ignore_index=True)


def test_summarize_counts_rates_and_intervals_per_cell(two_cells):
    summary = summarize(two_cells)
    assert list(summary["planner"]) == ["CV_all", "No_agg_assess"]
    assert list(summary["samples"]) == [40, 30]
    for _, row in summary.iterrows():
        cell = two_cells[two_cells["planner"] == row["planner"]]
        for col in RATE_COLUMNS:
            k = int(cell[col].sum())
            lo, hi = wilson_interval(k, len(cell))
            assert row[f"{col}_rate"] == pytest.approx(k / len(cell))
            assert (row[f"{col}_lo"], row[f"{col}_hi"]) == pytest.approx((float(lo), float(hi)))
        assert row["mean_completion_time_s"] == pytest.approx(cell["completion_time_s"].mean(), nan_ok=True)
    assert summary.loc[0, "success_rate"] > summary.loc[1, "success_rate"]


def test_summarize_by_other_columns_and_result_summary(two_cells):
    by_type = summarize(two_cells, by=("planner", "follower_aggressive"))
    assert by_type["samples"].sum() == len(two_cells)
    assert {"planner", "follower_aggressive", "success_lo", "collision_hi"} <= set(by_type.columns)
    one = simulate("CV_all", 1, 4.0, 10, seed=2, config=SimConfig(horizon_s=2.0))
    summary = one.summary()  # the rates of summarize(), after the run's preset and nominal planner
    assert (summary.loc[0, "preset"], summary.loc[0, "nominal"]) == (None, "expert")
    pd.testing.assert_frame_equal(summary.drop(columns=["preset", "nominal"]), summarize(one.table))
