"""The faster core (issue 13): the compiled evasion kernel beside the NumPy path, measured in one run on one thread.

Prints, never asserts (timings depend on the machine and on what else runs on it):

* the kernels' JIT compile time — a fresh process with an empty numba cache (``NUMBA_CACHE_DIR`` a new temporary
  directory) imports the part kernels and runs the fused loop once, then a second process loads both from that
  cache; ``import numba`` alone is timed too, since it is part of both;
* ``evasion_exists`` checks/s at batch 10^6 (``bench_safety``'s realistic states) on the NumPy path
  (``SAFELANE_NO_NUMBA=1``) and on the kernel, through the public function (input validation included), the two
  interleaved, best of ``--repeat`` rounds each, with the verdicts compared; beside the wall-clock rate, the rate
  per CPU second of this process (on a shared machine the wall clock also counts time the process waited);
* the same in the realistic world (the ``realistic`` preset: an own-lane leader L0, sensing error, actuation delay;
  its expert planner), N = 3: the default path (compiled where ``sim/_fused.reasons`` is empty, else period by
  period; the line says which) on 10^4 scenarios beside the period-by-period path on ``--realistic-rows`` of the same
  scenarios (2,000 by default: its tables are compared with the default path's rows), vehicles counted with L0;
* the closed-loop simulator's vehicle-steps/s at N = 3, batch 10^4 (``bench_sim``'s setting) on three paths,
  interleaved, with their tables compared: the NumPy path (``SAFELANE_NO_NUMBA=1``), the loop period by period with
  its part kernels (``SAFELANE_NO_FUSED=1``: the previous implementation) and the fused loop (the default,
  ``sim/_fast_loop.py``); then the period-by-period paths' time part by part.

The pass/MISS words compare the rate per CPU second with the target (a one-core figure that a loaded machine
does not halve); the wall-clock rate is printed beside it.

One thread: ``OMP_NUM_THREADS=1`` (set here before NumPy loads) and ``threadpoolctl`` limits; the kernel itself is
single-threaded. Run ``python benchmarks/bench_core.py [--repeat 5] [--quick]``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before NumPy loads: one-core figures

import argparse
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_safety import random_states
from safelane import Params
from safelane.safety import evasion_exists
from safelane.safety.evasion import fast_kernel
from safelane.sim import SimConfig, paper_scenarios, simulate_batch

TARGET_CHECKS = 6e6  # checks/s at batch 1e6, one core
TARGET_SIM = 25e6  # vehicle-steps/s at N = 3, batch 1e4, one core (the full supervisor, default settings)
TARGET_REAL = 15e6  # vehicle-steps/s at N = 3, one core, the realistic preset (L0, sensing error, actuation delay)
_COMPILE = """
import time
import numpy as np
import safelane.safety
t0 = time.perf_counter()
import numba
t1 = time.perf_counter()
from safelane.safety import _fast
from safelane.shield import _fast_decide, _fast_monitor
from safelane.sim import _fast_checks, _fast_traffic, paper_scenarios, simulate_batch
t2 = time.perf_counter()
simulate_batch(paper_scenarios("CV_all", 3, 5.0, 64, np.random.default_rng(0)))  # compiles the fused loop
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def compile_times() -> tuple[float, float, float, float, float]:
    """``(import numba, part kernels with an empty cache, part kernels from the cache, fused loop with an empty cache,
    fused loop from the cache)`` in seconds, each in a fresh process (the part kernels compile at their first call,
    ``_fast_base.kernel``; the fused loop at its first run, here 64 scenarios)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        runs = []
        for _ in range(2):
            out = subprocess.run([sys.executable, "-c", _COMPILE], env=env, capture_output=True, text=True, check=True)
            runs.append([float(x) for x in out.stdout.split()])
    return runs[1][0], runs[0][1], runs[1][1], runs[0][2], runs[1][2]


def timed(fn) -> tuple[float, float]:
    """``(wall, cpu)`` seconds of one call."""
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def interleaved(paths: dict, repeat: int) -> dict:
    """Best ``(wall, cpu)`` of ``repeat`` rounds per path, the paths alternating within each round."""
    best = {name: (float("inf"), float("inf")) for name in paths}
    for _ in range(repeat):
        for name, fn in paths.items():
            w, c = timed(fn)
            best[name] = (min(best[name][0], w), min(best[name][1], c))
    return best


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")


def with_env(fn, name: str = "SAFELANE_NO_NUMBA"):
    """``fn`` with ``name=1``: ``SAFELANE_NO_NUMBA`` the NumPy reference path, ``SAFELANE_NO_FUSED`` the closed loop
    period by period with its part kernels (the previous implementation)."""

    def call():
        os.environ[name] = "1"
        try:
            return fn()
        finally:
            del os.environ[name]

    return call


numpy_path = with_env


#: The closed loop's parts timed separately: (label, module, class or None, attribute) of the functions wrapped with
#: a CPU timer.
PARTS = (
    ("shield step (candidate checks, monitor, plans)", "safelane.shield.core", None, "step"),
    ("traffic (leaders, F)", "safelane.sim.step", "ClosedLoop", "others_accels"),
    ("chain analysis", "safelane.sim.step", "ClosedLoop", "chain"),
    ("collision checks and motion", "safelane.sim.step", "ClosedLoop", "check_and_advance"),
)


def part_times(run) -> tuple[dict[str, float], float]:
    """``({part: CPU s}, total CPU s)`` of one ``run()`` with each of :data:`PARTS` wrapped in a CPU timer."""
    import importlib

    spent = dict.fromkeys([label for label, *_ in PARTS], 0.0)
    saved = []
    for label, module, cls, name in PARTS:
        target = importlib.import_module(module)
        target = getattr(target, cls) if cls else target
        real = getattr(target, name)

        def timed_part(*a, _real=real, _label=label, **k):
            c = time.process_time()
            try:
                return _real(*a, **k)
            finally:
                spent[_label] += time.process_time() - c

        saved.append((target, name, real))
        setattr(target, name, timed_part)
    try:
        c = time.process_time()
        run()
        total = time.process_time() - c
    finally:
        for target, name, real in saved:
            setattr(target, name, real)
    return spent, total


def realistic_world(n_sim: int, repeat: int, base_rows: int) -> None:
    """The realistic preset's closed loop (N = 3): the default path beside the period-by-period one, rates per CPU s."""
    from safelane import load_preset
    from safelane.sim import _fused

    preset = load_preset("realistic")
    prm, cfg, expert = preset.params, preset.sim, preset.expert()
    steps = round(cfg.horizon_s / prm.dt)
    batch = paper_scenarios("CV_all", 3, 5.0, n_sim, np.random.default_rng(3))
    small = batch.take(np.arange(min(base_rows, n_sim)))
    why = _fused.reasons(batch, cfg, expert, None, False, False)
    run = lambda b: simulate_batch(b, seed=0, params=prm, config=cfg, nominal=expert).table  # noqa: E731
    full = lambda: run(batch)  # noqa: E731
    periods = with_env(lambda: run(small), "SAFELANE_NO_FUSED")
    a, b = full(), periods()
    identical = all(_same(np.asarray(a[k])[: len(small)], b[k]) for k in b)
    best = interleaved({"default": full, "per period": periods}, max(1, repeat // 2))
    path = "compiled loop" if not why else "period by period (" + "; ".join(why) + ")"
    print(
        f"\nsimulate_batch, realistic preset, CV_all, N = 3, {steps} steps; default path: {path}; the first "
        f"{len(small):,} rows identical on both paths: {identical}"
    )
    for name, rows in (("default", n_sim), ("per period", len(small))):
        w, c = best[name]
        work = (3 + 4) * steps * rows  # ego, F, L1..L3, L4 = L(N+1), L0
        ratio = "" if name == "per period" else f"   {best['per period'][1] / len(small) / (c / rows):5.2f}x CPU"
        mark = "pass" if work / c >= TARGET_REAL else "MISS"
        print(
            f"  {name:<11} {rows:>6,} scenarios {work / w / 1e6:6.2f} M vehicle-steps/s wall ({w:5.2f} s), "
            f"{work / c / 1e6:6.2f} M per CPU s{ratio}   target >= {TARGET_REAL / 1e6:g} M: {mark}"
        )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="rounds per figure (the best counts)")
    ap.add_argument("--quick", action="store_true", help="batch 10^5 checks and 10^3 scenarios, 2 rounds")
    ap.add_argument("--realistic-rows", type=int, default=2000, help="scenarios of the realistic world's baseline")
    args = ap.parse_args(argv)
    os.environ.pop("SAFELANE_NO_NUMBA", None)
    n_checks, n_sim = (100_000, 1_000) if args.quick else (1_000_000, 10_000)
    repeat = 2 if args.quick else args.repeat
    prm = Params()
    print(
        f"bench_core: {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs, "
        f"Python {platform.python_version()}, NumPy {np.__version__}, one thread, best of {repeat} (interleaved)"
    )
    kernel = fast_kernel()
    if kernel is None:
        print("numba is not installed (pip install 'safelane[fast]'): only the NumPy path can be timed")
    else:
        import numba

        numba_import, cold, warm, loop_cold, loop_warm = compile_times()
        print(
            f"kernels (numba {numba.__version__}): importing the part kernels' modules {cold:.2f} s with an empty "
            f"cache, {warm:.2f} s with it (each kernel compiles, or loads from the cache, at its first call); the "
            f"fused loop's first run in {loop_cold:.2f} s, {loop_warm:.2f} s from the cache (64 scenarios, the part "
            f"kernels it calls included); import numba itself {numba_import:.2f} s; "
            "benchmarks/bench_cold_start.py times a whole first run"
        )

    with threadpool_limits(1):
        states = random_states(np.random.default_rng(0), n_checks, prm)
        check = lambda: evasion_exists(**states, params=prm)  # noqa: E731
        same = bool((check() == numpy_path(check)()).all())
        paths = {"NumPy path": numpy_path(check)}
        if kernel is not None:
            paths["kernel"] = check
        best = interleaved(paths, repeat)
        print(f"\nevasion_exists at batch {n_checks:,} (validation included); verdicts equal: {same}")
        base = best["NumPy path"]
        for name, (w, c) in best.items():
            ratio = "" if name == "NumPy path" else f"   {base[0] / w:4.2f}x wall, {base[1] / c:4.2f}x CPU"
            mark = "pass" if n_checks / c >= TARGET_CHECKS else "MISS"
            print(
                f"  {name:<11} {n_checks / w / 1e6:6.2f} M checks/s wall ({w * 1e3:7.1f} ms), "
                f"{n_checks / c / 1e6:6.2f} M per CPU s{ratio}   target >= {TARGET_CHECKS / 1e6:g} M/s: {mark}"
            )

        cfg = SimConfig()
        steps = round(cfg.horizon_s / prm.dt)
        batch = paper_scenarios("CV_all", 3, 5.0, n_sim, np.random.default_rng(3))
        work = (3 + 3) * steps * n_sim
        run = lambda: simulate_batch(batch, seed=0, params=prm, config=cfg).table  # noqa: E731
        periods = with_env(run, "SAFELANE_NO_FUSED")
        tables = [run(), periods(), numpy_path(run)()]
        identical = all(_same(t[k], tables[0][k]) for t in tables[1:] for k in tables[0])
        paths = {"NumPy path": numpy_path(run), "per period": periods, "fused loop": run}
        best = interleaved(paths, repeat)
        print(
            f"\nsimulate_batch, CV_all, N = 3, batch {n_sim:,}, {steps} steps; results identical on the three paths: "
            f"{identical}"
        )
        for name, (w, c) in best.items():
            mark = "pass" if work / c >= TARGET_SIM else "MISS"
            ratio = "" if name == "NumPy path" else f"   {best['NumPy path'][1] / c:4.2f}x CPU"
            print(
                f"  {name:<11} {work / w / 1e6:6.2f} M vehicle-steps/s wall ({w:5.2f} s), {work / c / 1e6:6.2f} M per "
                f"CPU s{ratio}   target >= {TARGET_SIM / 1e6:g} M: {mark}"
            )
        # Where the period-by-period path's time goes, part by part (one more run of each path, CPU seconds, timers
        # included; the fused loop has no parts to time)
        numpy_parts, numpy_total = part_times(numpy_path(run))
        parts, total = part_times(periods) if kernel is not None else (numpy_parts, numpy_total)
        print(f"\n  {'part (CPU s per run)':<48} {'NumPy path':>10} {'per period':>10} {'ratio':>7}")
        rows = [*((label, numpy_parts[label], parts[label]) for label, *_ in PARTS)]
        rows.append(("the rest (nominal planner, observation, glue)", numpy_total - sum(numpy_parts.values()),
                     total - sum(parts.values())))  # fmt: skip
        rows.append(("whole run", numpy_total, total))
        for label, a, b in rows:
            print(f"  {label:<48} {a:10.3f} {b:10.3f} {a / b:6.2f}x")
        realistic_world(n_sim, repeat, args.realistic_rows)
    load = os.getloadavg()
    print(f"\nload average at the end: {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} logical CPUs")


if __name__ == "__main__":
    main()
