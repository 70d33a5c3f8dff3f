"""Safety campaign of issue 3: ≥ 20,000 random scenarios per planner variant, p_v = 0.

Scenarios: the paper's sampler with N ∈ {0, 1, 3, 5, 10} (equal shares), ``a_x_N+1_d ~ U[2, 8]`` m/s² drawn per
scenario, mixed follower types (half connected — collaborative and saying so —, a quarter non-connected
collaborative, a quarter non-connected aggressive) and 20 % human-driven connected leaders (see
``tests/sim_scenarios.py``). Each variant runs twice on the same scenarios: with the aggressiveness assessment
replaced by the truth (the paper's guarantee: zero collisions and zero ``p_m`` violations) and with the real,
observed assessment (no guarantee; the collision rate is reported with its 95 % Wilson interval).

Run with ``python benchmarks/campaign_safety.py [--samples 20000] [--seed 0] [--noise 0.1]`` (``--noise`` adds a
third pass, observed with that sensor noise). It prints; it asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the named scenario builders

from safelane.planners.variants import VARIANT_NAMES
from safelane.sim import SimConfig, simulate_batch, wilson_interval
from sim_scenarios import mixed_campaign_batch

COUNTS = ("collision", "safety_violation", "leader_collision", "leader_violation")


def run_variant(planner: str, samples: int, seed: int, cfg: SimConfig, chunk: int) -> pd.DataFrame:
    """The campaign for one variant, in chunks (same scenarios for every variant and assessment mode)."""
    rng = np.random.default_rng(seed)
    tables = []
    for start in range(0, samples, chunk):
        size = min(chunk, samples - start)
        batch = mixed_campaign_batch(planner, size, rng, first_id=start)
        tables.append(simulate_batch(batch, seed=seed, config=cfg).table)
    return pd.concat(tables, ignore_index=True)


def report(table: pd.DataFrame, seconds: float) -> str:
    n = len(table)
    k = int(table["collision"].sum())
    lo, hi = wilson_interval(k, n)
    counts = "  ".join(f"{c}={int(table[c].sum())}" for c in COUNTS)
    aggressive = table[table["follower_aggressive"]]
    return (
        f"n={n}  {counts}  collision rate={k / n:.5f} [{float(lo):.5f}, {float(hi):.5f}]  "
        f"success={table['success'].mean():.3f}  aggressive-F p_m violations="
        f"{int(aggressive['safety_violation'].sum())}/{len(aggressive)}  ({seconds:.0f} s)"
    )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20_000, help="scenarios per variant")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chunk", type=int, default=5_000, help="scenarios per simulated batch")
    ap.add_argument(
        "--noise", type=float, default=0.0, help="also run the observed assessment with this sensor noise std [m/s]"
    )
    args = ap.parse_args(argv)
    print(
        f"safety campaign: {args.samples} scenarios per variant, N in {{0,1,3,5,10}}, a_x_N+1_d ~ U[2, 8], "
        f"mixed F types, p_v = 0, seed {args.seed}"
    )
    modes = {"truth": SimConfig(assessment="truth"), "observed": SimConfig(assessment="observed")}
    if args.noise > 0:
        modes[f"observed, noise {args.noise} m/s"] = SimConfig(assessment="observed", sensor_noise_std=args.noise)
    total = {mode: [] for mode in modes}
    for mode, cfg in modes.items():
        print(f"\nassessment = {mode!r}")
        for planner in VARIANT_NAMES:
            t0 = time.perf_counter()
            table = run_variant(planner, args.samples, args.seed, cfg, args.chunk)
            total[mode].append(table)
            print(f"  {planner:<14}{report(table, time.perf_counter() - t0)}", flush=True)
    print()
    for mode, tables in total.items():
        table = pd.concat(tables, ignore_index=True)
        k, n = int(table["collision"].sum()), len(table)
        lo, hi = wilson_interval(k, n)
        print(
            f"all variants, assessment={mode!r}: {k} collisions / {n} = {k / n:.6f} "
            f"(95 % Wilson [{float(lo):.6f}, {float(hi):.6f}]), "
            f"{int(table['safety_violation'].sum())} p_m violations"
        )


if __name__ == "__main__":
    main()
