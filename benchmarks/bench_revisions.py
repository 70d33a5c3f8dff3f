"""The batched simulator's throughput at several git revisions, measured in one run (a baseline beside the figure).

Each revision is checked out into a temporary worktree and timed in a fresh interpreter with its own ``src`` on
``PYTHONPATH``, alternating revisions round by round so that a busy machine disturbs them alike; the best of the
rounds counts (as ``timeit`` does). The workload is ``bench_sim``'s: ``simulate_batch`` of the paper's sampler,
``CV_all``, the expert planner, the full supervisor, a 10 s horizon, at batch ``--batch`` for each N. A revision's
behaviour models may differ (then the simulated scenarios differ too): the table says which.

Run with ``python benchmarks/bench_revisions.py REV [REV ...] [--batch 10000] [--rounds 3] [--leaders 1 3 10]``,
e.g. ``HEAD~1 HEAD``. Prints, never asserts.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_PROBE = r"""
import json, sys, time
import numpy as np
from safelane import Params
from safelane.sim import SimConfig, paper_scenarios, simulate_batch
n, batch = int(sys.argv[1]), int(sys.argv[2])
scen = paper_scenarios("CV_all", n, 5.0, batch, np.random.default_rng(n))
simulate_batch(scen.take(np.arange(50)), seed=0)  # warm-up: imports, allocator
t0 = time.perf_counter()
table = simulate_batch(scen, seed=0, params=Params(), config=SimConfig()).table
dt = time.perf_counter() - t0
print(json.dumps({"s": dt, "veh_steps": (n + 3) * 100 * batch, "success": float(table["success"].mean())}))
"""


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("revs", nargs="+", help="git revisions (e.g. HEAD~1 HEAD)")
    ap.add_argument("--batch", type=int, default=10_000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--leaders", type=int, nargs="+", default=[1, 3, 10])
    args = ap.parse_args(argv)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {}
        for i, rev in enumerate(args.revs):
            tree = Path(tmp) / f"rev{i}"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), rev], check=True,
                           capture_output=True)  # fmt: skip
            trees[rev] = tree
        try:
            best = {(rev, n): None for rev in args.revs for n in args.leaders}
            for _ in range(args.rounds):
                for n in args.leaders:
                    for rev, tree in trees.items():
                        out = subprocess.run(
                            [sys.executable, "-c", _PROBE, str(n), str(args.batch)], check=True, capture_output=True,
                            text=True, env={**env, "PYTHONPATH": str(tree / "src")},
                        )  # fmt: skip
                        res = json.loads(out.stdout.strip().splitlines()[-1])
                        if best[(rev, n)] is None or res["s"] < best[(rev, n)]["s"]:
                            best[(rev, n)] = res
        finally:
            for tree in trees.values():
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False,
                               capture_output=True)  # fmt: skip
    base = args.revs[0]
    print(f"batched simulator, CV_all, batch {args.batch}, best of {args.rounds} rounds (alternating revisions)\n")
    print(f"{'N':>3} {'revision':>12} {'M veh-steps/s':>14} {'vs ' + base:>12} {'success':>8}")
    for n in args.leaders:
        ref = best[(base, n)]
        for rev in args.revs:
            r = best[(rev, n)]
            rate = r["veh_steps"] / r["s"]
            print(f"{n:>3} {rev:>12} {rate / 1e6:>14.2f} {ref['s'] / r['s']:>11.2f}x {r['success']:>8.3f}")


if __name__ == "__main__":
    main()
