"""The calibration's wall time on local processes and on Ray, measured in one run, and projected for N workers
(issue 13; docs/scale.md).

Measured: a reduced ``calibrate`` (default 4 candidates + 2 refinement steps + 1 finalist, 100 scenarios per Table 1
cell: 40 cells, 4,000 scenarios per candidate) with 1 process, 2 processes and 2 Ray tasks on a fresh local Ray
instance (its start timed apart); the three must find the same losses. Projected: the calibration parallelises
inside each candidate's batch, so a candidate costs ``a + c * B / N`` on N workers (``a``: the batch's fixed cost,
the Python loop over time steps; ``c``: per scenario; both fitted here on one core) plus the per-batch dispatch
overhead ``d`` measured here (Ray: a round trip of N empty tasks; processes: a pool's start). The projection
assumes N free cores of this speed and ignores transfer time on a network: it is a projection, not a measurement.

    .venv/bin/python benchmarks/bench_backends.py [--candidates 4 --refine 2 --finalists 1 --samples 100]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from safelane.experiments.calibration import calibrate, candidate_to_preset, published_cells
from safelane.experiments.grid import cell_batch
from safelane.parallel import Backend, map_chunks, probe, ray_available, ray_session
from safelane.sim.engine import simulate_batch
from safelane.sim.scenario import concat

FULL = {"candidates": 64, "refine": 32, "finalists": 4, "samples": 100, "final_samples": 400}  # `safelane calibrate`


def timed(fn, *args, **kwargs):
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - start, out


def fit_batch_cost(samples: int, seed: int = 0) -> tuple[float, float]:
    """``(a, c)`` of ``t(b) = a + c * b`` for one candidate's batch on one core (least squares over 4 sizes)."""
    preset = candidate_to_preset({})
    batch = concat([cell_batch(c, samples, seed, None) for c in published_cells()])
    sizes = [len(batch) // k for k in (8, 4, 2, 1)]
    times = []
    for b in sizes:
        rows = np.linspace(0, len(batch) - 1, b).astype(int)  # every cell represented
        t, _ = timed(simulate_batch, batch.take(rows), seed, params=preset.params, config=preset.sim,
                     nominal=preset.nominal())  # fmt: skip
        times.append(t)
    c, a = np.polyfit(sizes, times, 1)
    return max(a, 0.0), max(c, 0.0)


def calibration_time(a, c, d, n: int, spec: dict) -> float:
    """Projected wall time of a calibration with ``spec`` on ``n`` workers (see the module docstring)."""
    per = lambda b: a + c * b / n + d  # noqa: E731
    b1, b2 = 40 * spec["samples"], 40 * spec["final_samples"]
    return (spec["candidates"] + spec["refine"]) * per(b1) + spec["finalists"] * per(b2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", type=int, default=4)
    ap.add_argument("--refine", type=int, default=2)
    ap.add_argument("--finalists", type=int, default=1)
    ap.add_argument("--samples", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    spec = {"candidates": a.candidates, "refine": a.refine, "finalists": a.finalists, "samples": a.samples,
            "final_samples": a.samples, "seed": 0}  # fmt: skip
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the start (shared machine)")
    print(f"calibration: {a.candidates} candidates + {a.refine} refinement steps + {a.finalists} finalist(s), "
          f"{a.samples} scenarios per cell x 40 cells = {40 * a.samples} scenarios per candidate")  # fmt: skip
    results = {}
    t1, (_, f1) = timed(calibrate, **spec, workers=1)
    results["process, 1 worker (in-process)"] = t1
    t2, (_, f2) = timed(calibrate, **spec, workers=a.workers)
    results[f"process, {a.workers} workers"] = t2
    same = f1["loss"].equals(f2["loss"])
    d_ray = None
    if ray_available():
        t_start = time.perf_counter()
        with ray_session(num_cpus=a.workers):
            t_start = time.perf_counter() - t_start
            map_chunks(probe, [(0.0, 0.0)] * a.workers, "ray", a.workers)  # workers up (their start is timed apart)
            t3, (_, f3) = timed(calibrate, **spec, workers=Backend("ray", a.workers))
            d_ray = min(timed(map_chunks, probe, [(0.0, 0.0)] * a.workers, "ray", a.workers)[0] for _ in range(10))
        results[f"ray, {a.workers} tasks per batch (local instance; start {t_start:.1f} s not included)"] = t3
        same = same and f1["loss"].equals(f3["loss"])
    else:
        print("ray is not installed (pip install 'safelane[ray]'): the Ray row is missing")
    print("\nmeasured wall time of the reduced calibration:")
    for label, t in results.items():
        print(f"  {label:<75s} {t:7.1f} s  ({t1 / t:.2f}x the 1-process time)")
    print(f"  same losses on every backend: {same}")
    if not same:
        raise SystemExit("DIFFERENT results across backends")

    a_fix, c = fit_batch_cost(a.samples)
    d_proc = min(timed(map_chunks, probe, [(0.0, 0.0)] * a.workers, "process", a.workers)[0] for _ in range(3))
    print(f"\nfit on one core: a candidate's batch costs {a_fix:.2f} s + {c * 1e3:.3f} ms per scenario; dispatch "
          f"per batch: processes {d_proc * 1e3:.0f} ms (a pool's start)"
          + (f", Ray {d_ray * 1e3:.0f} ms" if d_ray is not None else ""))  # fmt: skip
    print(f"PROJECTION (not measured) for the full calibration ({FULL['candidates']}+{FULL['refine']} candidates x "
          f"{40 * FULL['samples']} scenarios, {FULL['finalists']} finalists x {40 * FULL['final_samples']}), "
          "N free cores of this speed:")  # fmt: skip
    d = d_ray if d_ray is not None else d_proc
    base = calibration_time(a_fix, c, 0.0, 1, FULL)
    for n in (1, 2, 4, 8, 16, 32, 64):
        t = calibration_time(a_fix, c, 0.0 if n == 1 else d, n, FULL)
        print(f"  N = {n:3d}: {t / 60:6.1f} min  ({base / t:5.1f}x)")
    print(f"  limit (N -> inf): {calibration_time(a_fix, 0.0, d, 1, FULL) / 60:.1f} min: the per-batch fixed cost "
          "(time steps in Python) bounds batch-level parallelism")  # fmt: skip


if __name__ == "__main__":
    main()
