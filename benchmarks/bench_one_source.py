"""The one source of the evasion check, uncompiled and compiled, in the same run.

``evasion_parts`` (``safety/evasion.py``) is the check of Eqs. 5–9 written once against ``xp``. The NumPy path
evaluates it on arrays (``SAFELANE_NO_NUMBA=1``: what mutation testing and a machine without numba run); the
kernels of ``safety/_fast.py`` compile the same function with numba and call it once per row. This script times both
on the same random states (``bench_safety.random_states``) and checks that they agree bit for bit; then the first
compile of the kernels in a fresh process with an empty numba cache, and a later start that loads them.

Run with ``python benchmarks/bench_one_source.py [--n 1000000] [--repeat 5]``. It prints; it asserts nothing but
the bit-for-bit agreement (timings depend on what else runs on the machine).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_safety import random_states
from safelane import Params
from safelane.safety import evasion as ev
from safelane.safety._backend import ARRAY


def best_of(repeat: int, fn) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def fresh_process_seconds(cache_dir: str) -> float:
    """Wall time of a fresh interpreter that imports the closed loop's kernels and runs one tiny simulation."""
    code = (
        "import numpy as np\n"
        "from safelane.sim import paper_scenarios, simulate_batch\n"
        "simulate_batch(paper_scenarios('CV_all', 3, 5.0, 64, np.random.default_rng(0)), seed=0)\n"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, env=env)
    return time.perf_counter() - t0


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="states per batch")
    ap.add_argument("--repeat", type=int, default=5, help="timed runs (the best counts)")
    ap.add_argument("--no-compile", action="store_true", help="skip the cold-compile measurement")
    args = ap.parse_args(argv)
    prm = Params()
    states = random_states(np.random.default_rng(0), args.n, prm)
    inputs = ev._prepare_evasion(*(states[k] for k in ev._PLAN_INPUTS), states["follower_aggressive"], prm,
                                 False, False)[1]  # fmt: skip
    kernel = ev.fast_kernel()
    if kernel is None:
        sys.exit("numba is not installed (or SAFELANE_NO_NUMBA=1): nothing compiled to compare")
    shape = (args.n,)
    with np.errstate(all="ignore"):
        ref_exists, *ref_fields = ev.evasion_parts(ARRAY, *inputs, prm)
    exists, parts = kernel.run_plan(inputs, shape, prm, ev.FEASIBILITY_TOL_M)
    same = bool(np.array_equal(exists, ref_exists))
    for name, ref in zip(ev.PARTS, ref_fields, strict=True):
        a, b = np.broadcast_to(parts[name], shape), np.broadcast_to(ref, shape)
        same &= bool(np.array_equal(a, b) or np.array_equal(a, b, equal_nan=True))
    if not same:
        sys.exit("the compiled rows and the NumPy path disagree: a bug")
    print(f"bench_one_source: evasion_parts on {args.n:,} random states, best of {args.repeat}; every output field "
          "bit-identical between the two paths\n")  # fmt: skip
    print(f"{'path':<44} {'M checks/s':>11} {'vs NumPy':>9}")

    def numpy_path():
        with np.errstate(all="ignore"):
            ev.evasion_parts(ARRAY, *inputs, prm)

    base = args.n / best_of(args.repeat, numpy_path) / 1e6
    print(f"{'NumPy path (uncompiled, the same function)':<44} {base:>11.2f} {1.0:>8.2f}x")
    plan = args.n / best_of(args.repeat, lambda: kernel.run_plan(inputs, shape, prm, ev.FEASIBILITY_TOL_M)) / 1e6
    print(f"{'compiled rows, whole plan (plan_kernel)':<44} {plan:>11.2f} {plan / base:>8.2f}x")
    verdict = args.n / best_of(args.repeat, lambda: kernel.run(inputs, shape, prm, ev.FEASIBILITY_TOL_M)) / 1e6
    print(f"{'compiled rows, verdict only (exists_kernel)':<44} {verdict:>11.2f} {verdict / base:>8.2f}x")
    if not args.no_compile:
        with tempfile.TemporaryDirectory() as cache:
            cold = fresh_process_seconds(cache)
            warm = fresh_process_seconds(cache)
        print(f"\nfresh process, empty numba cache (compiles every kernel): {cold:.1f} s; the next start (cached): "
              f"{warm:.1f} s")  # fmt: skip
    print(f"\nload average at the end: {' '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
