"""Rebuild a run's report and figures from its folder, without simulating: ``run.json`` and the CSVs in ``data/``.

Used to publish a run into ``docs/results/`` (the per-scenario CSVs stay out of the repository; the report says
where they come from) and to look at the report's layout in seconds (``benchmarks/report_screenshot.py``)::

    python -m safelane.reporting.rebuild results/<run-id> docs/results   # copy the summaries, redraw, rewrite

The numbers are the run's: summaries, trace, claims and Table 1 side by side are recomputed from the CSVs the run
wrote, with the same functions ``safelane reproduce`` uses, and the copied CSVs are the run's bytes.
"""

from __future__ import annotations

import argparse
import json
import shutil
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from ..experiments.calibration import load_preset
from ..experiments.claims import check_claims, table1_side_by_side
from ..experiments.registry import EXPERIMENTS
from ..experiments.runner import ExperimentResult
from .figures import FIGURES
from .report import RunRecord, write_report

#: The files of a run that are published (small); per-scenario tables are not.
PUBLISHED = ("_summary.csv", "_trace.csv", "claims.csv", "table1_side_by_side.csv")


def record_from_folder(folder: str | Path, *, figures: bool | Sequence[str] = True) -> RunRecord:
    """A :class:`RunRecord` from a run folder (``run.json`` and ``data/``); figures are redrawn into ``figures/``
    (``figures``: all, none, or the experiments named)."""
    folder = Path(folder)
    info = json.loads((folder / "run.json").read_text(encoding="utf-8"))
    preset = load_preset(info["preset"]["name"])
    results: dict[str, ExperimentResult] = {}
    for name, config in info["configs"].items():
        exp = EXPERIMENTS[name]

        def read(kind: str, name: str = name) -> pd.DataFrame | None:
            path = folder / "data" / f"{name}_{kind}.csv"
            return pd.read_csv(path) if path.exists() else None

        summary, trace = read("summary"), read("trace")
        elapsed = float(info.get("timings_s", {}).get(name, 0.0))
        results[name] = ExperimentResult(name, exp.config_type(**config), None, summary, trace, elapsed)
    summaries = {n: r.summary for n, r in results.items() if r.summary is not None and EXPERIMENTS[n].feeds_claims}
    trace = results["fig5_example"].trace if "fig5_example" in results else None
    claims = check_claims(summaries, fig5_trace=trace)
    side, mae = (None, None)
    if "table1" in summaries:
        side, mae = table1_side_by_side(summaries["table1"])
    drawn = {}
    for name, res in results.items():
        data = res.summary if res.summary is not None else res.trace
        wanted = figures is True or (not isinstance(figures, bool) and name in figures)
        if wanted and name in FIGURES and data is not None and len(data):
            drawn[name] = [p.resolve() for p in FIGURES[name](data, folder / "figures", preset.params.y_boundary)]
    data_files = []
    for name, res in results.items():
        kinds = ("scenarios", "summary") if res.summary is not None else ("trace",)
        data_files += [Path("data") / f"{name}_{kind}.csv" for kind in kinds]
    data_files += [Path("data/claims.csv")] + ([Path("data/table1_side_by_side.csv")] if side is not None else [])
    timings = {k: float(v) for k, v in info.get("timings_s", {}).items()}
    return RunRecord(
        run_id=info["run_id"], run_dir=folder.resolve(), seed=info["seed"], quick=info["quick"],
        command=info["command"], preset=preset, results=results, claims=claims, side_by_side=side, mae=mae,
        figures=drawn, data_files=data_files, versions=info["versions"], parquet=info.get("parquet", False),
        timings=timings, started_utc=info["started_utc"],
    )  # fmt: skip


def rebuild(folder: str | Path) -> tuple[Path, Path]:
    """Redraw the figures and rewrite ``report.md`` and ``report.html`` of a run folder from its data."""
    return write_report(record_from_folder(folder))


def publish(run_dir: str | Path, dest: str | Path) -> tuple[Path, Path]:
    """Copy a run's small CSVs and ``run.json`` to ``dest`` (e.g. ``docs/results``), then rebuild its report there.

    The per-scenario CSVs are not copied; the report lists them as not committed, with the command that writes
    them.
    """
    run_dir, dest = Path(run_dir), Path(dest)
    (dest / "data").mkdir(parents=True, exist_ok=True)
    for csv in sorted((run_dir / "data").glob("*.csv")):
        if csv.name.endswith(PUBLISHED):
            shutil.copyfile(csv, dest / "data" / csv.name)
    shutil.copyfile(run_dir / "run.json", dest / "run.json")
    return rebuild(dest)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m safelane.reporting.rebuild", description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path, help="a run folder of `safelane reproduce` (run.json and data/)")
    ap.add_argument("dest", type=Path, nargs="?", help="publish into this folder (default: rebuild in place)")
    args = ap.parse_args(argv)
    md, page = publish(args.run_dir, args.dest) if args.dest else rebuild(args.run_dir)
    print(f"{md}\n{page}")


if __name__ == "__main__":
    main()
