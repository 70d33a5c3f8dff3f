"""Throughput of the neural planner: batched inference samples/s, and its share of a simulation step.

Run with ``python benchmarks/bench_nn.py [--quick] [--model PATH]``. Prints, for batch sizes 1, 1e3, 1e4 and 1e5:
the NumPy forward pass alone (``predict`` on precomputed features), the full planner call (features + forward +
clipping) and, when installed, ONNX Runtime (1 thread). Then the wall time of ``simulate`` with the MLP as the
nominal planner against the rule-based expert, and the share of a step the MLP call takes. Asserts nothing:
timings depend on the machine and on what else runs on it. BLAS threads follow ``OMP_NUM_THREADS``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from safelane import Params
from safelane.planners.base import ExpertPlanner
from safelane.planners.features import features
from safelane.planners.nn import MLPPlanner, load_default_planner
from safelane.training.data import DataConfig, sample_observations


def _seconds_per_call(fn, repeats: int, budget_s: float = 0.2) -> float:
    """Median over ``repeats`` rounds of the mean wall time of one call; a round lasts at least ``budget_s``."""
    fn()
    rounds = []
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while True:
            fn()
            calls += 1
            elapsed = time.perf_counter() - start
            if elapsed >= budget_s:
                break
        rounds.append(elapsed / calls)
    return statistics.median(rounds)


class _Timed:
    """Wraps a planner and accumulates the wall time spent inside it."""

    def __init__(self, planner):
        self.planner, self.seconds, self.calls = planner, 0.0, 0

    def __call__(self, obs, params):
        start = time.perf_counter()
        out = self.planner(obs, params)
        self.seconds += time.perf_counter() - start
        self.calls += 1
        return out


def bench_inference(planner: MLPPlanner, params: Params, sizes, repeats: int) -> None:
    onnx = None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            onnx = MLPPlanner.from_onnx(planner.to_onnx(Path(tmp) / "m.onnx"))
    except ImportError as exc:
        print(f"(ONNX Runtime path skipped: {exc})")
    print(f"{'batch':>8} {'predict [samples/s]':>20} {'planner call':>14} {'onnxruntime':>12} {'us/call (B=1)':>14}")
    for n in sizes:
        obs = sample_observations(n, np.random.default_rng(0), params, DataConfig())
        x = features(obs, params)
        t_pred = _seconds_per_call(lambda x=x: planner.predict(x), repeats)
        t_call = _seconds_per_call(lambda obs=obs: planner(obs, params), repeats)
        t_onnx = _seconds_per_call(lambda x=x: onnx.predict(x), repeats) if onnx else float("nan")
        extra = f"{1e6 * t_call:14.1f}" if n == 1 else ""
        print(f"{n:>8} {n / t_pred:20.3g} {n / t_call:14.3g} {n / t_onnx:12.3g} {extra}")


def bench_simulation(planner: MLPPlanner, samples: int) -> None:
    from safelane.sim import simulate

    for name, nominal in (("expert", ExpertPlanner()), ("mlp", planner)):
        timed = _Timed(nominal)
        start = time.perf_counter()
        simulate("CV_all", n_leaders=3, decel=4.0, samples=samples, seed=0, nominal=timed)
        total = time.perf_counter() - start
        print(f"simulate({samples} scenarios, {timed.calls} steps) with {name:6s}: {total:6.2f} s, "
              f"{1e3 * total / timed.calls:6.2f} ms/step, nominal planner {100 * timed.seconds / total:4.1f} % "
              f"of the step")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, no 1e5 batch, smaller simulation")
    ap.add_argument("--model", type=Path, default=None, help="a model .npz (default: the shipped planner)")
    args = ap.parse_args()
    planner = MLPPlanner.load(args.model) if args.model else load_default_planner()
    params = Params()
    shapes = {h: [w.shape for w, _ in planner.layers[h]] for h in planner.layers}
    print(f"model: {planner.activation} MLPs {shapes}")
    sizes = (1, 1_000, 10_000) if args.quick else (1, 1_000, 10_000, 100_000)
    bench_inference(planner, params, sizes, repeats=3 if args.quick else 5)
    bench_simulation(planner, samples=1_000 if args.quick else 10_000)


if __name__ == "__main__":
    main()
