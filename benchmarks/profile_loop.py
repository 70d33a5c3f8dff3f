"""Where the compiled closed loop's time goes, line by line, in the build that runs (every row function inlined).

``perf`` sees numba's code as anonymous memory, and with everything inlined into ``_fast_loop._loop_rows`` a perf
map of the functions would name one symbol. This script gets the lines instead: it compiles the loop with debug
information (``NUMBA_DEBUGINFO=1``, into a cache directory of its own, so the package's cache is untouched; the code
is otherwise the same optimised build), runs it under ``perf record``, takes the ELF object numba cached for
``loop_kernel`` (its ``.nbc`` file holds the object code), maps each sample's address to an offset in that object
through the address the running process reports for ``_loop_rows``, and symbolizes the offsets with
``llvm-symbolizer --inlining``: every sample gets its chain of inlined frames, source file and line.

It prints the share of the loop's samples per function (inclusive: a sample counts for every frame it is inside),
per call site in ``_period`` / ``_loop_rows`` (the part of the period) and per line of ``period_row`` (the shield).
Shares of an out-of-order core's samples say where instructions waited, not what a change would save: measure a
change with ``bench_core.py`` / ``bench_falsify.py``.

    .venv/bin/python benchmarks/profile_loop.py [--world core|falsify] [--rows 20000] [--cache DIR]

``core``: ``bench_core``'s setting (CV_all, N = 3, the expert planner); ``falsify``: ``bench_falsify``'s paper world
(rounds of random, cross-entropy and knife-edge specs, the adversarial planners as data). Needs ``perf`` (with
``perf_event_paranoid`` <= 2) and ``llvm-symbolizer``; the first run compiles the loop (minutes).
"""

from __future__ import annotations

import argparse
import collections
import glob
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def child(world: str, rows: int) -> None:
    """The profiled run: compile (or load) the loop, report ``_loop_rows``' address, then run it."""
    import numpy as np

    from safelane import Params
    from safelane.sim import SimConfig, _fast_loop, paper_scenarios, simulate_batch

    if world == "core":
        batch = paper_scenarios("CV_all", 3, 5.0, rows, np.random.default_rng(3))
        simulate_batch(batch.take(np.arange(64)), seed=0, params=Params(), config=SimConfig())
        run = lambda: simulate_batch(batch, seed=0, params=Params(), config=SimConfig())  # noqa: E731
    else:
        sys.path.insert(0, str(HERE))
        import bench_falsify as bf

        setting = bf._setting("paper")
        rounds = bf.round_specs("paper", max(2, rows // 6144 + 1), 2048)
        bf.per_round(rounds[0], setting)
        run = lambda: [bf.per_round(specs, setting) for specs in rounds[1:]]  # noqa: E731
    obj_path = os.path.join(os.environ["NUMBA_CACHE_DIR"], "loop.o")  # the object numba cached, loaded in this process
    Path(obj_path).write_bytes(loop_object(os.environ["NUMBA_CACHE_DIR"]))
    names = subprocess.run(["readelf", "-sW", obj_path], capture_output=True, text=True, check=True).stdout.split()
    name = next(n for n in names if "_loop_rows" in n and not n.startswith(("_ZN7cpython", "cfunc.")))
    for cres in _fast_loop.loop_kernel.overloads.values():
        address = cres.library.get_pointer_to_function(name)
        if address:
            print(f"LOOP_ROWS {address:x} {name}", flush=True)
    cpu = time.process_time()
    run()
    print(f"CPU {time.process_time() - cpu:.3f}", flush=True)


def loop_object(cache: str) -> bytes:
    """The ELF object in ``loop_kernel``'s cache file (the last written, if several)."""
    files = sorted(glob.glob(os.path.join(cache, "sim_*", "_fast_loop.loop_kernel-*.nbc")), key=os.path.getmtime)
    raw = Path(files[-1]).read_bytes()
    at = raw.find(b"\x7fELF")
    shoff = struct.unpack_from("<Q", raw, at + 0x28)[0]
    shentsize, shnum = struct.unpack_from("<HH", raw, at + 0x3A)
    return raw[at : at + shoff + shentsize * shnum]


def symbol_offset(obj_path: str, name: str) -> tuple[int, int]:
    """``(offset, size)`` of the function ``name`` in its section of the object."""
    out = subprocess.run(["readelf", "-sW", obj_path], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 8 and parts[3] == "FUNC" and parts[7] == name:
            return int(parts[1], 16), int(parts[2], 0)
    raise SystemExit(f"{name} not found in the cached object")


def report(counts: collections.Counter, obj_path: str) -> None:
    offsets = [f"0x{o:x}" for o in counts]
    cmd = ["llvm-symbolizer", f"--obj={obj_path}", "--inlining", "--functions=short"]
    out = subprocess.run(cmd, input="\n".join(offsets) + "\n", capture_output=True, text=True, check=True).stdout
    blocks = out.strip("\n").split("\n\n")
    total = sum(counts.values())
    inclusive, sites, shield = collections.Counter(), collections.Counter(), collections.Counter()
    for n, block in zip(counts.values(), blocks, strict=True):
        lines = block.split("\n")
        pairs = zip(lines[0::2], lines[1::2], strict=False)  # (function, file:line:column), innermost first
        frames = [(fn, at.split("/safelane/")[-1].rsplit(":", 1)[0]) for fn, at in pairs]
        for fn in {f for f, _ in frames}:
            inclusive[fn] += n
        for i, (fn, where) in enumerate(frames):
            if fn in ("_period", "_loop_rows"):
                sites[f"{where:<28} {frames[i - 1][0] if i else '(the line itself)'}"] += n
                break
        for i, (fn, where) in enumerate(frames):
            if fn == "period_row":
                shield[f"{where:<28} {frames[i - 1][0] if i else '(the line itself)'}"] += n
    print(f"{total} samples in _loop_rows")
    for title, counter, rows in (("function (inclusive)", inclusive, 30), ("call site in the period", sites, 25),
                                 ("line of period_row (the shield)", shield, 15)):  # fmt: skip
        print(f"\n  {title}")
        for key, n in counter.most_common(rows):
            print(f"  {100 * n / total:6.2f} %  {key}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", choices=("core", "falsify"), default="core")
    ap.add_argument("--rows", type=int, default=20_000, help="scenarios (core), or about that many specs (falsify)")
    ap.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "safelane-profile-cache"),
                    help="numba cache of the debug-info build (kept: later runs load it)")  # fmt: skip
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.world, args.rows)
        return
    missing = [tool for tool in ("perf", "llvm-symbolizer", "readelf") if shutil.which(tool) is None]
    if missing:
        raise SystemExit(f"profile_loop.py needs {', '.join(missing)} on the PATH")
    env = dict(os.environ, NUMBA_DEBUGINFO="1", NUMBA_CACHE_DIR=args.cache, OMP_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        cmd = ["perf", "record", "-q", "-F", "1999", "-o", data, sys.executable, __file__, "--child", "--world",
               args.world, "--rows", str(args.rows)]  # fmt: skip
        out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
        found = [line.split() for line in out.splitlines() if line.startswith("LOOP_ROWS")]
        if not found:
            raise SystemExit("the compiled loop did not run (see _fused.reasons)")
        address, name = int(found[0][1], 16), found[0][2]
        print(next(line for line in out.splitlines() if line.startswith("CPU")), "s in the timed run")
        obj_path = os.path.join(args.cache, "loop.o")
        offset, size = symbol_offset(obj_path, name)
        ips = subprocess.run(["perf", "script", "-i", data, "-F", "ip"], capture_output=True, text=True,
                             check=True).stdout.split()  # fmt: skip
        counts = collections.Counter()
        for ip in ips:
            at = int(ip, 16) - address
            if 0 <= at < size:
                counts[offset + at] += 1
        report(counts, obj_path)


if __name__ == "__main__":
    main()
