"""Throughput of the batched closed-loop simulator vs a per-scenario Python loop on the scalar safety API.

*Batched*: ``simulate_batch`` — the full supervisor (proceed / hesitate / abort) with the expert planner, the
``CV_all`` variant, the paper's sampler, a 10 s horizon — at batch 10,000 for N = 1, 3 and 10.
*Loop*: the same closed loop re-implemented for one scenario at a time with Python floats, calling the scalar
safety API (``worst_case_leader_decel``, ``plan_evasion``, ``EvasionPlan.state``) per scenario per step — what one
would write without batching (``tests/scalar_loop.py``; it makes the engine's decisions, see
``tests/test_sim_scalar_loop.py``). It runs on an evenly spaced subset of the same scenarios (every
``batch / loop``-th) and is compared per vehicle-step.

Vehicle-steps = (N + 3 vehicles: ego, F, L1..L(N+1)) × steps × scenarios. Targets: ≥ 2 M vehicle-steps/s batched,
≥ 100× over the loop. Both run in this one process, on one core (the ratio compares like with like); a last
column times the batch split over ``--workers`` processes (``simulate_batch(workers=...)``), for what the
machine's cores give together. The batched time is the best of ``--repeat``
runs (as ``timeit`` does: the least disturbed); the loop runs once over its subset. Run with
``python benchmarks/bench_sim.py [--batch 10000] [--loop 100] [--repeat 3] [--quick]``; it prints, never asserts
(timings depend on the machine and on what else runs on it).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from safelane import Params
from safelane.sim import SimConfig, paper_scenarios, simulate_batch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the scalar loop lives with the tests

from scalar_loop import loop_scenario

TARGET_BATCHED = 2e6  # vehicle-steps/s
TARGET_RATIO = 100.0
PLANNER = "CV_all"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=10_000, help="scenarios per batched run")
    ap.add_argument("--loop", type=int, default=100, help="scenarios through the per-scenario loop")
    ap.add_argument("--repeat", type=int, default=3, help="batched runs per N (the best counts)")
    ap.add_argument("--leaders", type=int, nargs="+", default=[1, 3, 10])
    ap.add_argument("--decel", type=float, default=5.0, help="a_x_N+1_d [m/s²]")
    ap.add_argument("--workers", type=int, default=2, help="also time the batch split over this many processes")
    ap.add_argument("--quick", action="store_true", help="batch 1000, loop 5 (a smoke run)")
    args = ap.parse_args(argv)
    if args.quick:
        args.batch, args.loop, args.repeat = 1000, 5, 1
    prm, cfg = Params(), SimConfig()
    steps = round(cfg.horizon_s / prm.dt)
    print(
        f"bench_sim: {PLANNER}, expert planner, full supervisor, horizon {cfg.horizon_s:g} s ({steps} steps), "
        f"a_x_N+1_d = {args.decel:g}, batch {args.batch} (best of {args.repeat}), loop over {args.loop} of the same "
        "scenarios"
    )
    print(f"targets: batched >= {TARGET_BATCHED / 1e6:g} M vehicle-steps/s, batched/loop >= {TARGET_RATIO:g}x\n")
    header = (
        f"{'N':>3} {'batched [M veh-steps/s]':>24} {'loop [k veh-steps/s]':>21} {'ratio':>8} "
        f"{f'{args.workers} processes [M]':>15}  outcome agreement"
    )
    print(header)
    for n in args.leaders:
        batch = paper_scenarios(PLANNER, n, args.decel, args.batch, np.random.default_rng(n))
        vehicles = n + 3
        best = float("inf")
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            table = simulate_batch(batch, seed=0, params=prm, config=cfg).table
            best = min(best, time.perf_counter() - t0)
        batched = vehicles * steps * args.batch / best
        best_par = float("inf")
        for _ in range(args.repeat if args.workers > 1 else 0):
            t0 = time.perf_counter()
            simulate_batch(batch, seed=0, params=prm, config=cfg, workers=args.workers)
            best_par = min(best_par, time.perf_counter() - t0)
        parallel = vehicles * steps * args.batch / best_par
        subset = np.linspace(0, args.batch - 1, min(args.loop, args.batch)).round().astype(int)
        t0 = time.perf_counter()
        loop_rows = [loop_scenario(batch, i, prm, steps) for i in subset]
        looped = vehicles * steps * len(subset) / (time.perf_counter() - t0)
        same = sum(
            row["success"] == table["success"][i] and row["collision"] == table["collision"][i]
            for i, row in zip(subset, loop_rows, strict=True)
        )
        mark = "ok" if batched >= TARGET_BATCHED else "below target"
        ratio = batched / looped
        print(
            f"{n:>3} {batched / 1e6:>17.2f} ({mark:>5}) {looped / 1e3:>21.1f} {ratio:>7.0f}x "
            f"{parallel / 1e6:>15.2f}  success/collision equal in {same}/{len(subset)}"
        )


if __name__ == "__main__":
    main()
