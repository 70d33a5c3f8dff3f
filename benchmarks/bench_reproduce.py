"""Benchmark: wall time of ``reproduce()`` per experiment and in total (issue 5's target: full grid <= 60 s on the
2-core machine). Prints figures; asserts nothing.

    .venv/bin/python benchmarks/bench_reproduce.py            # the full default grid (1,000 scenarios per cell)
    .venv/bin/python benchmarks/bench_reproduce.py --quick    # the reduced grid
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
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run = reproduce(
            args.out or tmp, seed=args.seed, quick=args.quick, workers=args.workers, preset=args.preset, progress=False
        )
        total = time.perf_counter() - start
        timings = json.loads((run / "run.json").read_text())["timings_s"]
        scenarios = {
            p.name.removesuffix("_scenarios.csv"): len(pd.read_csv(p, usecols=["scenario_id"]))
            for p in (run / "data").glob("*_scenarios.csv")
        }

    print(f"reproduce(quick={args.quick}, workers={args.workers}) on {os.cpu_count()} CPUs")
    print(f"{'step':<20}{'seconds':>10}{'scenarios':>12}{'scen/s':>10}")
    for step, seconds in timings.items():
        n = scenarios.get(step)
        rate = f"{n / seconds:10.0f}" if n else f"{'':>10}"
        print(f"{step:<20}{seconds:10.2f}{(n or ''):>12}{rate}")
    print(f"{'total (wall)':<20}{total:10.2f}{sum(scenarios.values()):>12}")
    verdict = "within" if total <= TARGET_S else "over"
    grid = "quick grid" if args.quick else "full grid"
    print(f"target <= {TARGET_S:.0f} s for the full grid: {verdict} ({total:.1f} s, {grid})")


if __name__ == "__main__":
    main()
