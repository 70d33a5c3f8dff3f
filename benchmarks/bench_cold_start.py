"""A first run's compile time and a later start, phase by phase: each in a fresh process, first with empty caches
(``NUMBA_CACHE_DIR`` and ``PYTHONPYCACHEPREFIX`` new temporary folders: what a fresh install pays once), then again
on the caches it left (every later start; the best of ``--repeat`` runs). The phases: importing ``safelane.sim``; the
first compiled-loop run (64 scenarios, the expert); the first run of the paper preset's neural planner on the
compiled period; the first step of ``gymnasium.make("safelane/LaneChange-v0")``. The issue's targets: a first run
<= 15 s, a later start <= 1 s. Each phase on the wall clock and in CPU time of the child (on a machine shared with
other work the wall clock also counts the time others held the core; the CPU time much less).

Python's bytecode cache is on in the children as Python keeps it by default: a later start reads the package's
compiled ``.pyc`` files. (This sandbox sets ``PYTHONDONTWRITEBYTECODE=1``; the children drop it and keep their
bytecode under the temporary ``PYTHONPYCACHEPREFIX``, so nothing is written into the tree.) Printed beside, from the
same run: a later start without the bytecode cache (``PYTHONDONTWRITEBYTECODE=1``, every module compiled from source
at each start), and the floor no package on these dependencies can go under: importing NumPy, pandas, pydantic,
numba and Gymnasium alone. SciPy, where installed, adds to numba's first load (numba imports ``scipy.linalg`` to find
a BLAS); the run says whether it is.

    .venv/bin/python benchmarks/bench_cold_start.py [--repeat 3] [--later-only]

``--later-only``: no first run; the numba cache is the tree's own (warmed by one untimed run first).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile

PHASES = r"""
import time
clock = time.perf_counter if WALL else time.process_time
t0 = clock()
import numpy as np
from safelane.sim import paper_scenarios, simulate_batch
from safelane.sim.preset import load_preset
marks = [("import safelane.sim", clock())]
batch = paper_scenarios("CV_all", 3, 5.0, 64, np.random.default_rng(0))
simulate_batch(batch)
marks.append(("first compiled-loop run (expert)", clock()))
preset = load_preset("paper")
simulate_batch(batch, params=preset.params, config=preset.sim, nominal=preset.nominal())
marks.append(("first neural-planner run (compiled period)", clock()))
import gymnasium
import safelane.envs  # noqa: F401  (registers the envs)
env = gymnasium.make("safelane/LaneChange-v0")
env.reset(seed=0)
env.step(np.zeros(2))
marks.append(("first env step", clock()))
last = t0
for name, t in marks:
    print(f"{name}\t{t - last:.3f}")
    last = t
print(f"total\t{last - t0:.3f}")
"""

FLOOR = r"""
import time
t0, c0 = time.perf_counter(), time.process_time()
import numpy, pandas, pydantic, numba, gymnasium  # noqa: F401, E401
print(f"{time.perf_counter() - t0:.3f}\t{time.process_time() - c0:.3f}")
"""


def _env(numba_cache: str | None, pyc: str | None) -> dict:
    """The children's environment: numba's cache folder (None: the tree's own) and Python's bytecode cache (a
    folder, or None: off, as ``PYTHONDONTWRITEBYTECODE=1``)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")}
    if numba_cache is not None:
        env["NUMBA_CACHE_DIR"] = numba_cache
    if pyc is None:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    else:
        env["PYTHONPYCACHEPREFIX"] = pyc
    return env


def phases(env: dict) -> list[tuple[str, float, float]]:
    """``(phase, wall s, CPU s)``: the phases run twice in fresh processes, once on each clock (the first run on
    the wall clock fills the caches when they are empty)."""
    got = {}
    for wall in (True, False):
        code = f"WALL = {wall}\n" + PHASES
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
        got[wall] = [(name, float(t)) for name, t in (line.split("\t") for line in out.strip().splitlines())]
    return [(name, w, c) for (name, w), (_, c) in zip(got[True], got[False], strict=True)]


def best(runs: list[list[tuple[str, float, float]]]) -> list[tuple[str, float, float]]:
    """Per phase, the run with the least total CPU time."""
    return min(runs, key=lambda r: r[-1][2])


def floor(repeat: int) -> tuple[float, float]:
    outs = [subprocess.run([sys.executable, "-c", FLOOR], env=_env(None, None), capture_output=True, text=True,
                           check=True).stdout for _ in range(repeat)]  # fmt: skip
    pairs = [tuple(float(x) for x in o.split()) for o in outs]
    return min(pairs, key=lambda p: p[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="later starts timed (the best is printed)")
    ap.add_argument("--later-only", action="store_true", help="no first run: the tree's numba cache, warmed first")
    args = ap.parse_args()
    scipy = importlib.util.find_spec("scipy") is not None
    print(f"SciPy installed: {scipy} (numba imports scipy.linalg at its first load where it is)")
    with tempfile.TemporaryDirectory() as numba_cache, tempfile.TemporaryDirectory() as pyc:
        cache = None if args.later_only else numba_cache
        first = phases(_env(cache, pyc))
        warm = best([phases(_env(cache, pyc)) for _ in range(args.repeat)])
        no_pyc = best([phases(_env(cache, None)) for _ in range(args.repeat)])
    clocks = f" {'wall':>9s} {'CPU':>9s}"
    head = "" if args.later_only else f" {'first run':>19s}"
    print(f"{'phase':44s}{head} {'later start':>19s} {'without .pyc':>19s}")
    print(f"{'':44s}{'' if args.later_only else clocks}{clocks}{clocks}")
    for k, (name, w, c) in enumerate(warm):
        cold = "" if args.later_only else f" {first[k][1]:7.2f} s {first[k][2]:7.2f} s"
        print(f"{name:44s}{cold} {w:7.2f} s {c:7.2f} s {no_pyc[k][1]:7.2f} s {no_pyc[k][2]:7.2f} s")
    fw, fc = floor(args.repeat)
    print(f"{'floor: import numpy, pandas, pydantic, numba, gymnasium':44s}{'' if args.later_only else ' ' * 20} "
          f"{fw:7.2f} s {fc:7.2f} s")
    if not args.later_only:
        total = first[-1][1]
        print(f"  first run {'pass' if total <= 15.0 else 'MISS'} against <= 15 s ({total:.1f} s wall)")
    w, c = warm[-1][1], warm[-1][2]
    print(f"  later start {'pass' if w <= 1.0 else 'MISS'} against <= 1 s on the wall clock ({w:.2f} s; "
          f"CPU {c:.2f} s, {'pass' if c <= 1.0 else 'MISS'})")


if __name__ == "__main__":
    main()
