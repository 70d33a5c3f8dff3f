"""A first run's compile time and a later start, phase by phase: each in a fresh process, first with an empty numba
cache (``NUMBA_CACHE_DIR`` a new temporary folder: what a fresh install pays once), then again on the cache it left
(every later start). The phases: importing ``safelane.sim``; the first compiled-loop run (64 scenarios, the expert);
the first run of the paper preset's neural planner on the compiled period; the first step of
``gymnasium.make("safelane/LaneChange-v0")``. The issue's targets: a first run ≤ 15 s, a later start ≤ 1 s.

    .venv/bin/python benchmarks/bench_cold_start.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

PHASES = r"""
import time
t0 = time.perf_counter()
import numpy as np
from safelane.sim import paper_scenarios, simulate_batch
from safelane.sim.preset import load_preset
marks = [("import safelane.sim", time.perf_counter())]
batch = paper_scenarios("CV_all", 3, 5.0, 64, np.random.default_rng(0))
simulate_batch(batch)
marks.append(("first compiled-loop run (expert)", time.perf_counter()))
preset = load_preset("paper")
simulate_batch(batch, params=preset.params, config=preset.sim, nominal=preset.nominal())
marks.append(("first neural-planner run (compiled period)", time.perf_counter()))
import gymnasium
import safelane.envs  # noqa: F401  (registers the envs)
env = gymnasium.make("safelane/LaneChange-v0")
env.reset(seed=0)
env.step(np.zeros(2))
marks.append(("first env step", time.perf_counter()))
last = t0
for name, t in marks:
    print(f"{name}\t{t - last:.2f}")
    last = t
print(f"total\t{last - t0:.2f}")
"""


def phases(cache: str) -> list[tuple[str, float]]:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    out = subprocess.run([sys.executable, "-c", PHASES], env=env, capture_output=True, text=True, check=True).stdout
    return [(name, float(t)) for name, t in (line.split("\t") for line in out.strip().splitlines())]


def main() -> None:
    with tempfile.TemporaryDirectory() as cache:
        cold = phases(cache)
        warm = phases(cache)
    print(f"{'phase':44s} {'empty cache':>12s} {'cached':>8s}")
    for (name, c), (_, w) in zip(cold, warm, strict=True):
        print(f"{name:44s} {c:10.2f} s {w:6.2f} s")
    total_cold, total_warm = cold[-1][1], warm[-1][1]
    print(f"  first run {'pass' if total_cold <= 15.0 else 'MISS'} against <= 15 s ({total_cold:.1f} s); "
          f"later start {'pass' if total_warm <= 1.0 else 'MISS'} against <= 1 s ({total_warm:.2f} s)")


if __name__ == "__main__":
    main()
