"""Benchmark: the wall time of ``reproduce()``'s "figures and files" step (tables, claims, figures) the way it ran
before ``write_files`` beside the way it runs now, on the same simulated results. Prints figures; asserts nothing.

    .venv/bin/python benchmarks/bench_report_files.py                 # full grid, simulated once with --workers 2
    .venv/bin/python benchmarks/bench_report_files.py --quick         # the reduced grid
    .venv/bin/python benchmarks/bench_report_files.py --results r.pkl # reuse (or first save) the simulated results

The experiments run once; each way then writes the run's files from those results in a fresh Python process (so
each pays its own imports, as ``reproduce`` does), ``--repeat`` times; the best and every time are printed:

* ``before``: the step as it was (commit be3af69): one process, ``DataFrame.to_csv``, each figure's constrained
  layout solved for the PNG and again for the SVG;
* ``now, 1 worker`` and ``now, N workers``: :func:`safelane.experiments.reproduce.write_files`.

Every way's CSVs are compared byte for byte, and its set of figure files.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict
from pathlib import Path


def before(results, run_dir: Path, preset) -> None:
    """The step as ``reproduce`` ran it before ``write_files`` (one process, pandas, the layout solved twice)."""
    import pandas as pd

    from safelane.experiments.claims import check_claims, table1_side_by_side
    from safelane.experiments.registry import EXPERIMENTS
    from safelane.reporting import figures, rss

    for name, res in results.items():
        for kind, frame in (("scenarios", res.table), ("summary", res.summary), ("trace", res.trace)):
            if frame is not None:
                frame.to_csv(run_dir / "data" / f"{name}_{kind}.csv", index=False)
    summaries = {n: r.summary for n, r in results.items() if r.summary is not None and EXPERIMENTS[n].feeds_claims}
    fig5 = results["fig5_example"].trace if "fig5_example" in results else None
    claims = check_claims(summaries, fig5_trace=fig5)
    pd.DataFrame([asdict(c) for c in claims]).to_csv(run_dir / "data" / "claims.csv", index=False)
    if "table1" in summaries:
        table1_side_by_side(summaries["table1"])[0].to_csv(run_dir / "data" / "table1_side_by_side.csv", index=False)

    def save_twice(fig, out_dir: Path, stem: str) -> list[Path]:  # figures._save before the layout was kept
        import matplotlib

        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        png, svg = out_dir / f"{stem}.png", out_dir / f"{stem}.svg"
        with matplotlib.rc_context({"svg.hashsalt": "safelane"}):
            fig.savefig(png, dpi=figures.DPI, metadata={"Software": None})
            fig.savefig(svg, metadata={"Date": None})
        return [png, svg]

    figures._save = rss._save = save_twice
    for name, res in results.items():
        data = res.summary if res.summary is not None else res.trace
        if name in figures.FIGURES and data is not None and len(data):
            figures.FIGURES[name](data, run_dir / "figures", preset.params.y_boundary)


def one_way(way: str, results_path: Path, out: Path, preset_name: str) -> None:
    """Child process: write the files one way; print the wall and CPU seconds (its worker processes' included) as
    JSON."""
    import resource

    from safelane.experiments.calibration import load_preset
    from safelane.experiments.reproduce import write_files

    results = pickle.loads(results_path.read_bytes())
    preset = load_preset(preset_name)
    (out / "data").mkdir(parents=True)

    def cpu() -> float:
        children = resource.getrusage(resource.RUSAGE_CHILDREN)  # the pool's workers, once joined
        return time.process_time() + children.ru_utime + children.ru_stime

    start, cpu0 = time.perf_counter(), cpu()
    if way == "before":
        before(results, out, preset)
    else:
        write_files(results, out, preset, int(way))
    print(json.dumps({"seconds": time.perf_counter() - start, "cpu_s": cpu() - cpu0}))


def simulate(args) -> dict:
    from safelane.experiments.calibration import load_preset
    from safelane.experiments.registry import EXPERIMENTS
    from safelane.experiments.reproduce import _run_all

    start = time.perf_counter()
    results = _run_all(list(EXPERIMENTS), {}, load_preset(args.preset), args.seed, args.quick, args.workers, False)
    print(f"simulated {sum(len(r.table) for r in results.values() if r.table is not None)} scenarios "
          f"in {time.perf_counter() - start:.1f} s (workers={args.workers})")  # fmt: skip
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the reduced grid instead of the paper's")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2, help="for the simulations and the new way (default 2)")
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--repeat", type=int, default=3, help="times each way runs (the best is reported)")
    parser.add_argument("--results", type=Path, default=None, help="pickled results: reused, or saved here first")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # child process: "before" or a worker count
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        one_way(args.one, args.results, args.out, args.preset)
        return
    with tempfile.TemporaryDirectory() as tmp:
        pkl = args.results or Path(tmp) / "results.pkl"
        if not pkl.exists():
            pkl.write_bytes(pickle.dumps(simulate(args)))
        ways = [("before", "before (1 process, pandas to_csv, layout solved per format)"),
                ("1", "now, 1 worker"), (str(args.workers), f"now, {args.workers} workers")]  # fmt: skip
        ways = list(dict(ways).items())  # --workers 1: "now, 1 worker" once
        times: dict[str, list[float]] = {way: [] for way, _ in ways}
        cpus: dict[str, list[float]] = {way: [] for way, _ in ways}
        files: dict[str, dict[str, bytes]] = {}
        for k in range(args.repeat):
            for way, _ in ways:
                out = Path(tmp) / f"{way}-{k}"
                cmd = [sys.executable, __file__, "--one", way, "--results", str(pkl), "--out", str(out)]
                cmd += ["--preset", args.preset]
                done = subprocess.run(cmd, check=True, capture_output=True, text=True)
                measured = json.loads(done.stdout.strip().splitlines()[-1])
                times[way].append(measured["seconds"])
                cpus[way].append(measured["cpu_s"])
                files[way] = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(f'"figures and files" step, {os.cpu_count()} CPUs (load average now {load}), best of {args.repeat}: '
          "wall time, and CPU time of all its processes (every run in brackets)")  # fmt: skip
    for way, label in ways:
        every = ", ".join(f"{t:.2f}" for t in times[way])
        every_cpu = ", ".join(f"{t:.2f}" for t in cpus[way])
        print(f"  {label:<62}{min(times[way]):7.2f} s [{every}]  CPU {min(cpus[way]):5.2f} s [{every_cpu}]")
    base = min(times["before"])
    for way, label in ways[1:]:
        print(f"  before / {label}: {base / min(times[way]):.1f}x")
    ref = files["before"]
    csvs = sorted(n for n in ref if n.endswith(".csv"))
    for way, label in ways[1:]:
        same_csv = all(files[way].get(n) == ref[n] for n in csvs)
        same_set = sorted(files[way]) == sorted(ref)
        same_png = all(files[way][n] == ref[n] for n in ref if n.endswith(".png"))
        print(f"  {label}: {len(csvs)} CSVs byte-identical to before: {same_csv}; same files: {same_set}; "
              f"PNGs byte-identical: {same_png}")  # fmt: skip


if __name__ == "__main__":
    main()
