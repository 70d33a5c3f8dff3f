"""Benchmark: wall time of ``reproduce()`` per experiment and in total (issue 5's target: full grid <= 60 s on the
2-core machine). Prints figures; asserts nothing.

    .venv/bin/python benchmarks/bench_reproduce.py            # the full default grid (1,000 scenarios per cell)
    .venv/bin/python benchmarks/bench_reproduce.py --quick    # the reduced grid
    .venv/bin/python benchmarks/bench_reproduce.py --baseline # also the NumPy path (SAFELANE_NO_NUMBA=1) first,
                                                              # the same run: both totals, and the CSVs compared
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import pandas as pd

from safelane.experiments.reproduce import reproduce

TARGET_S = 60.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the reduced grid instead of the paper's")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--out", type=Path, default=None, help="keep the run here (default: a temporary folder)")

    parser.add_argument("--baseline", action="store_true", help="also time the NumPy path (no compiled kernels)")
    args = parser.parse_args()
    paths = [("NumPy path (SAFELANE_NO_NUMBA=1)", "1")] if args.baseline else []
    paths.append(("default", None))
    totals, csvs = {}, {}
    for name, switch in paths:
        if switch is None:
            os.environ.pop("SAFELANE_NO_NUMBA", None)
        else:
            os.environ["SAFELANE_NO_NUMBA"] = switch
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            run = reproduce(
                args.out or tmp, seed=args.seed, quick=args.quick, workers=args.workers, preset=args.preset,
                progress=False,
            )  # fmt: skip
            total = time.perf_counter() - start
            timings = json.loads((run / "run.json").read_text())["timings_s"]
            scenarios = {
                p.name.removesuffix("_scenarios.csv"): len(pd.read_csv(p, usecols=["scenario_id"]))
                for p in (run / "data").glob("*_scenarios.csv")
            }
            csvs[name] = {p.name: p.read_bytes() for p in (run / "data").glob("*.csv")}
        totals[name] = total
        print(f"{name}: reproduce(quick={args.quick}, workers={args.workers}) on {os.cpu_count()} CPUs")
        print(f"{'step':<20}{'seconds':>10}{'scenarios':>12}{'scen/s':>10}")
        for step, seconds in timings.items():
            n = scenarios.get(step)
            rate = f"{n / seconds:10.0f}" if n else f"{'':>10}"
            print(f"{step:<20}{seconds:10.2f}{(n or ''):>12}{rate}")
        print(f"{'total (wall)':<20}{total:10.2f}{sum(scenarios.values()):>12}\n")
    os.environ.pop("SAFELANE_NO_NUMBA", None)
    if args.baseline:
        base, fast = (totals[name] for name, _ in paths)
        same = csvs[paths[0][0]] == csvs["default"]
        print(f"default / NumPy path: {fast:.1f} s / {base:.1f} s = {base / fast:.2f}x faster; "
              f"{len(csvs['default'])} CSVs byte-identical: {same}")  # fmt: skip
    verdict = "within" if total <= TARGET_S else "over"
    grid = "quick grid" if args.quick else "full grid"
    print(f"target <= {TARGET_S:.0f} s for the full grid: {verdict} ({total:.1f} s, {grid})")


if __name__ == "__main__":
    main()
