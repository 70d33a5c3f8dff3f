"""Accuracy and time to detection of the aggressiveness assessment on the scenario distribution.

Scenarios: the paper's sampler with N ∈ {0, 1, 3, 5, 10}, ``a_x_N+1_d ~ U[2, 8]`` m/s² per scenario, every follower
non-connected (so every one must be assessed), half of them aggressive; the ego runs ``CV_none``, whose
supervisor acts on the assessment. For each sensor-noise level it prints the accuracy of the final belief (overall
and per true type), the rate of the *unsafe* mistake (an aggressive follower ever believed collaborative) and
statistics of the time of the first "collaborative" verdict for collaborative followers.

Run with ``python benchmarks/assessment_report.py [--samples 4000] [--seed 0]``. It prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the named scenario builders

from safelane.sim import ScenarioConfig, SimConfig, simulate_batch, wilson_interval
from sim_scenarios import mixed_campaign_batch

UNCONNECTED = ScenarioConfig(follower_connected_share=0.0, follower_aggressive_share=0.5)
NOISE_LEVELS = (0.0, 0.02, 0.05, 0.1, 0.2)


def _rate(k: int, n: int) -> str:
    if n == 0:
        return "   n/a"
    lo, hi = wilson_interval(k, n)
    return f"{k / n:6.3f} [{float(lo):.3f}, {float(hi):.3f}]"


def summarize_assessment(table: pd.DataFrame) -> dict:
    collab = table[~table["follower_aggressive"]]
    aggressive = table[table["follower_aggressive"]]
    t = collab["assessment_time_s"].dropna()
    return {
        "accuracy": _rate(int(table["assessment_correct"].sum()), len(table)),
        "collab correct": _rate(int(collab["assessment_correct"].sum()), len(collab)),
        "aggr correct": _rate(int(aggressive["assessment_correct"].sum()), len(aggressive)),
        "aggr ever collab": _rate(int(aggressive["assessment_time_s"].notna().sum()), len(aggressive)),
        "collab by 1 s": _rate(int((collab["assessment_time_s"] <= 1.0).sum()), len(collab)),
        "t mean": f"{t.mean():.2f}" if len(t) else "n/a",
        "t median": f"{t.median():.2f}" if len(t) else "n/a",
        "t p95": f"{t.quantile(0.95):.2f}" if len(t) else "n/a",
        "t max": f"{t.max():.2f}" if len(t) else "n/a",
        "success": f"{table['success'].mean():.3f}",
        "collisions": int(table["collision"].sum()),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    batch = mixed_campaign_batch("CV_none", args.samples, np.random.default_rng(args.seed), config=UNCONNECTED)
    n_aggr = int(batch.follower_aggressive.sum())
    print(
        f"assessment report: {args.samples} scenarios ({n_aggr} aggressive, {args.samples - n_aggr} collaborative "
        "followers, none connected), N in {0,1,3,5,10}, a_x_N+1_d ~ U[2, 8], planner CV_none, 10 s horizon"
    )
    print("rates with 95 % Wilson intervals; t = time of the first 'collaborative' verdict of a collaborative F [s]\n")
    rows = {}
    for noise in NOISE_LEVELS:
        t0 = time.perf_counter()
        table = simulate_batch(batch, seed=args.seed, config=SimConfig(sensor_noise_std=noise)).table
        rows[f"noise {noise} m/s"] = summarize_assessment(table)
        print(f"  noise {noise} m/s done ({time.perf_counter() - t0:.0f} s)", flush=True)
    print()
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(pd.DataFrame(rows).to_string())
    truth = simulate_batch(batch, seed=args.seed, config=SimConfig(assessment="truth")).table
    print(f"\nfor comparison, the truth in place of the assessment: success {truth['success'].mean():.3f}")


if __name__ == "__main__":
    main()
