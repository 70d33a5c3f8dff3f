"""Closed-loop scenarios per second of the falsifier (docs/falsification.md), one core, beside the path it took before,
measured in the same run on the same scenarios.

For each world (``--worlds``) the same ``--rounds`` rounds of specs (one batch of ``--batch-size`` rows per method:
random, cross-entropy from its prior, knife edges; seeded) are simulated these ways, interleaved round by round so
that all see the same state of the machine:

* ``round``: the falsifier's path, :func:`safelane.experiments.falsify.evaluate_round` (a round's three batches as
  one simulation; in the paper's world in the compiled loop: the adversarial planners and the hooks as data,
  L(N+1)'s profiles compiled);
* ``period``: ``round`` on the compiled period, the adversarial planners in NumPy between its periods (the loop
  refused by the batch size it asks for: the falsifier's path before the planners were compiled);
* ``per batch``: :func:`~safelane.experiments.falsify.evaluate` per method's batch;
* ``before``: ``per batch`` period by period (``SAFELANE_NO_FUSED=1``: the engine every falsifier run took before
  the hooks and profiles were compiled, with its part kernels);
* ``numpy`` (``--numpy``): ``per batch`` in a child process with ``SAFELANE_NO_NUMBA=1`` (the NumPy reference).

Rates are simulated scenarios (rows inside the assumptions at ``t = 0``) over wall time and over this process's CPU
time (what a loaded machine does not halve; the targets, 10,000/s in the paper's world and 3,000/s in the realistic
one, are one core's), the first round (numba's compilation, the caches) left out; every way's outcomes must be
equal, row for row and bit for bit, or it stops.

    .venv/bin/python benchmarks/bench_falsify.py [--worlds paper realistic] [--rounds 4] [--batch-size 2048] [--numpy]
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import time

import numpy as np


def round_specs(world: str, rounds: int, batch_size: int) -> list[list[dict]]:
    """``rounds`` rounds of (random, cross-entropy prior, knife) specs, each from its own seed."""
    from safelane.experiments import falsify as fz
    from safelane.experiments import falsify_space as space

    setting = _setting(world)
    prm = setting.params
    dim = space.dimension(prm, world)
    out = []
    for i in range(rounds):
        rng = [np.random.default_rng([7, m, i]) for m in range(3)]
        cem = fz.CrossEntropy(dim).ask(rng[1], batch_size)
        out.append(
            [
                space.decode(rng[0].uniform(size=(batch_size, dim)), prm, 0.0, world),
                space.decode(cem, prm, 0.0, world),
                space.knife_specs(rng[2], batch_size, prm, 0.0, world),
            ]
        )
    return out


def _setting(world: str):
    from safelane.experiments import falsify as fz

    return (fz.Setting.realistic() if world == "realistic" else fz.Setting()).resolved()


def per_batch(specs: list[dict], setting) -> list:
    from safelane.experiments import falsify as fz

    return [fz.evaluate(spec, setting)[0] for spec in specs]


def per_round(specs: list[dict], setting) -> list:
    from safelane.experiments import falsify as fz

    return fz.evaluate_round(specs, setting)[0]


#: Scenarios per CPU second to reach, per world (one core).
TARGETS = {"paper": 10_000, "realistic": 3_000}


def timed(fn, *args) -> tuple[tuple[float, float], list]:
    """``((wall, cpu) seconds, fn(*args))``."""
    start, cpu = time.perf_counter(), time.process_time()
    out = fn(*args)
    return (time.perf_counter() - start, time.process_time() - cpu), out


def on_the_period(fn):
    """``fn`` with the compiled loop refused (``FUSED_MIN_ROWS`` above any batch): its compiled period runs."""
    from safelane.sim import _fused

    def call(*args):
        saved, _fused.FUSED_MIN_ROWS = _fused.FUSED_MIN_ROWS, 1 << 60
        try:
            return fn(*args)
        finally:
            _fused.FUSED_MIN_ROWS = saved

    return call


def same(a: list, b: list) -> bool:
    return all(x.reset_index(drop=True).equals(y.reset_index(drop=True)) for x, y in zip(a, b, strict=True))


def child(world: str, rounds: int, batch_size: int) -> None:
    """The NumPy reference (run with ``SAFELANE_NO_NUMBA=1``): per batch, pickled to stdout."""
    setting = _setting(world)
    walls, outs = [], []
    for specs in round_specs(world, rounds, batch_size):
        (wall, _), out = timed(per_batch, specs, setting)
        walls.append(wall)
        outs.append(out)
    sys.stdout.buffer.write(pickle.dumps((walls, outs)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["paper", "realistic"])
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--batch-size", type=int, default=2048)
    ap.add_argument("--numpy", action="store_true", help="also the NumPy reference (SAFELANE_NO_NUMBA=1), compared")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.rounds, args.batch_size)
        return
    for world in args.worlds:
        setting = _setting(world)
        rounds = round_specs(world, args.rounds + 1, args.batch_size)
        ways = {"round": (per_round, None), "period": (on_the_period(per_round), None),
                "per batch": (per_batch, None), "before": (per_batch, "SAFELANE_NO_FUSED")}  # fmt: skip
        walls = {name: [] for name in ways}
        cpus = {name: [] for name in ways}
        sims, outs = [], []
        for specs in rounds:
            got = {}
            for name, (fn, env) in ways.items():
                if env:
                    os.environ[env] = "1"
                try:
                    (wall, cpu), got[name] = timed(fn, specs, setting)
                finally:
                    os.environ.pop(env or "", None)
                walls[name].append(wall)
                cpus[name].append(cpu)
            if not all(same(got["round"], out) for out in got.values()):
                raise SystemExit(f"{world}: the ways' outcomes differ (a bug)")
            sims.append(sum(len(o) for o in got["round"]))
            outs.append(got["round"])
        if args.numpy:
            env = dict(os.environ, SAFELANE_NO_NUMBA="1")
            cmd = [sys.executable, __file__, "--child", world, "--rounds", str(args.rounds + 1), "--batch-size",
                   str(args.batch_size)]  # fmt: skip
            walls["numpy"], ref = pickle.loads(subprocess.run(cmd, env=env, capture_output=True, check=True).stdout)
            if not all(same(a, b) for a, b in zip(ref, outs, strict=True)):
                raise SystemExit(f"{world}: the NumPy path's outcomes differ from the compiled paths' (a bug)")
        n = sum(sims[1:])
        print(f"{world}: {args.rounds} rounds x 3 batches x {args.batch_size} rows, {n} simulated (first round left "
              f"out); outcomes equal{' (and to the NumPy path)' if args.numpy else ''}")  # fmt: skip
        base = sum(walls["before"][1:])
        for name, wall in walls.items():
            total = sum(wall[1:])
            cpu = sum(cpus[name][1:]) if name in cpus else float("nan")
            print(f"  {name:10s} {total:7.2f} s  {n / total:8.0f} scenarios/s  ({base / total:.2f}x before)   "
                  f"{n / cpu:8.0f} per CPU s")  # fmt: skip
        rate = n / sum(cpus["round"][1:])
        mark = "pass" if rate >= TARGETS[world] else "MISS"
        print(f"  target >= {TARGETS[world]:,} scenarios per CPU s ({world}): {mark} ({rate:,.0f})")


if __name__ == "__main__":
    main()
