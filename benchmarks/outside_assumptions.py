# ruff: noqa: E402  (the BLAS thread settings below must precede the first NumPy import)
"""Outside the assumptions, measured (issue 9): what breaks the guarantee, by how much, and what the assumption
monitor (``SimConfig.shield.monitor``) does about it.

Every setting runs the same scenarios — the paper's sampler, N ∈ {1, 3, 10}, ``a_x_N+1_d`` ∈ {4, 6} (8 for the
L(N+1)-beyond-``a_x_d`` rows: 10 and 12), F connected half of the time, non-connected F aggressive half of those —
with the supervisor's assessment replaced by the truth (the paper's guarantee assumes it) unless the setting is
about the assessment, once with the monitor on and once off. Columns: collision rate, ``p_m``-violation rate (ego),
leader-lane violation rate, the worst gap to F or L1 over ``p_m`` (exact where the pair came near), success rate,
and the share of scenarios where the monitor recorded a breach.

Run with ``python benchmarks/outside_assumptions.py [--samples 500] [--seed 0]``. Prints a Markdown table; asserts
nothing.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import dataclasses
import time
import warnings

import numpy as np
import pandas as pd

from safelane import Params
from safelane.reporting.document import Document
from safelane.sim import ScenarioConfig, SimConfig, concat, paper_scenarios, simulate_batch

TRUTH = SimConfig(assessment="truth")
MIXED_F = ScenarioConfig(follower_connected_share=0.5, follower_aggressive_share=0.5)

# name -> (variant, config, scenario edits, decels, p_v)
SETTINGS = {
    "inside the assumptions": ("CV_all", TRUTH, None, (4.0, 6.0), 0.0),
    "aggressive F believed collaborative": ("CV_follow", TRUTH, "connected_aggressive", (4.0, 6.0), 0.0),
    "observed assessment, sensor noise 0.2 m/s": (
        "CV_none", SimConfig(assessment="observed", sensor_noise_std=0.2), None, (4.0, 6.0), 0.0),
    "F ignores the ego": ("CV_follow", TRUTH.model_copy(update={"follower_ignores_ego": True}), None, (4.0, 6.0), 0.0),
    "p_v = 0.01": ("CV_all", TRUTH, None, (4.0, 6.0), 0.01),
    "p_v = 0.1": ("CV_all", TRUTH, None, (4.0, 6.0), 0.1),
    "p_v = 0.3": ("CV_all", TRUTH, None, (4.0, 6.0), 0.3),
    "L(N+1) brakes beyond a_x_d (10, 12 m/s²)": ("CV_all", TRUTH, None, (10.0, 12.0), 0.0),
    "V2X: 10 % of messages lost": ("CV_all", TRUTH.model_copy(update={"v2x_loss": 0.1}), None, (4.0, 6.0), 0.0),
    "V2X: 50 % of messages lost": ("CV_all", TRUTH.model_copy(update={"v2x_loss": 0.5}), None, (4.0, 6.0), 0.0),
    "V2X: 1 period late": ("CV_all", TRUTH.model_copy(update={"v2x_latency_periods": 1}), None, (4.0, 6.0), 0.0),
    "V2X: 3 periods late (0.3 s = max age: fresh)": (
        "CV_all", TRUTH.model_copy(update={"v2x_latency_periods": 3}), None, (4.0, 6.0), 0.0),
    "V2X: 10 periods late (stale)": (
        "CV_all", TRUTH.model_copy(update={"v2x_latency_periods": 10}), None, (4.0, 6.0), 0.0),
    "V2X: 8 periods late, max age 1 s (old messages trusted)": (
        "CV_all", TRUTH.model_copy(update={"v2x_latency_periods": 8, "v2x_max_age_s": 1.0}), None, (4.0, 6.0), 0.0),
}  # fmt: skip


def build(variant, edit, decels, p_v, samples, seed):
    rng = np.random.default_rng(seed)
    parts, first = [], 0
    for n in (1, 3, 10):
        for decel in decels:
            parts.append(paper_scenarios(variant, n, decel, samples, rng, MIXED_F, first_id=first, p_v=p_v))
            first += samples
    batch = concat(parts)
    if edit == "connected_aggressive":  # every F connected (declaring collaborative) but driving aggressively
        batch = dataclasses.replace(
            batch,
            connected=np.column_stack([np.ones(len(batch), bool), batch.connected[:, 1:]]),
            follower_aggressive=np.ones(len(batch), bool),
        )
    return batch


def measure(table: pd.DataFrame, p_m: float) -> dict:
    gap = np.fmin(table["min_gap_leader_m"], table["min_gap_follower_m"]) / p_m
    return {
        "collision": table["collision"].mean(),
        "p_m violation": table["safety_violation"].mean(),
        "leader violation": table["leader_violation"].mean(),
        "worst gap / p_m": float(np.nanmin(gap)) if gap.notna().any() else float("nan"),
        "success": table["success"].mean(),
        "breach seen": table["assumption_breach"].mean(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=500, help="scenarios per (N, decel) cell")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    prm = Params()
    rows = []
    start = time.perf_counter()
    for name, (variant, cfg, edit, decels, p_v) in SETTINGS.items():
        batch = build(variant, edit, decels, p_v, args.samples, args.seed)
        for monitor in (True, False):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # decel beyond a_x_d warns: that row is about exactly that
                table = simulate_batch(batch, args.seed, config=cfg.model_copy(update={"monitor": monitor})).table
            rows.append({"setting": name, "variant": variant, "monitor": "on" if monitor else "off",
                         "scenarios": len(table), **measure(table, prm.p_m)})  # fmt: skip
    out = pd.DataFrame(rows)
    print(f"{len(out) // 2} settings x monitor on/off, {out['scenarios'].sum()} scenarios, "
          f"{time.perf_counter() - start:.0f} s\n")  # fmt: skip
    doc = Document("Outside the assumptions")
    doc.table(
        list(out.columns),
        [[f"{x:.4f}" if isinstance(x, float) else x for x in row] for row in out.itertuples(index=False)],
    )
    print(doc.to_markdown())


if __name__ == "__main__":
    main()
