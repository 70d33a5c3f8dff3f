"""Reproduce the paper end to end: run every registered experiment and write figures, tables and a report.

``reproduce()`` writes ``<out_dir>/<run-id>/`` (run-id = UTC timestamp, seed and grid, e.g.
``20250101T120000Z-seed0-quick``)::

    data/<experiment>_scenarios.csv   per-scenario table (and .parquet when pyarrow is importable)
    data/<experiment>_summary.csv     per-cell rates with 95 % Wilson intervals
    data/fig5_example_trace.csv       the traced example scenario
    data/table1_side_by_side.csv      Table 1, ours beside the paper's
    data/claims.csv                   every claim with its verdict and evidence
    figures/<experiment>.png|.svg     the paper's Figures 4–6 redrawn, Table 1, and ours
    run.json                          seed, configs, preset, versions, command, timings
    report.md, report.html            the report (HTML self-contained)

The same seed reproduces every number: the CSVs are byte-identical between runs (timings live only in
``run.json`` and the report), on any number of workers. With ``workers`` > 1 the tables and figures are also written
on that many processes (:func:`write_files`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import gc
import importlib.util
import json
import platform
import shutil
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import pandas as pd
from pydantic import BaseModel

from ..parallel import Backend, as_backend, map_chunks
from .calibration import Preset, load_preset
from .claims import check_claims, table1_side_by_side
from .csv_writer import write_csv
from .registry import EXPERIMENTS, get_experiment
from .runner import ExperimentResult, run_experiment


def run_id(seed: int, quick: bool, now: dt.datetime | None = None) -> str:
    """``<UTC timestamp>-seed<seed>-<quick|full>``."""
    now = now or dt.datetime.now(dt.timezone.utc)
    return f"{now:%Y%m%dT%H%M%SZ}-seed{seed}-{'quick' if quick else 'full'}"


def reproduce(
    out_dir: str | Path | None = None,
    *,
    seed: int = 0,
    quick: bool = False,
    workers: int | Backend = 1,
    preset: str | Path | Preset = "paper",
    progress: bool = True,
    experiments: Sequence[str] | None = None,
    configs: Mapping[str, BaseModel] | None = None,
    command: str | None = None,
    nominal: str | Path | None = None,
) -> Path:
    """Run the experiments and write results, figures and the report; returns the run folder.

    ``out_dir`` is the parent folder (default ``results``). ``experiments`` selects a subset (default: all
    registered), ``configs`` overrides an experiment's config (default: its paper or ``quick`` config).
    ``command`` is the command line recorded in the report (default: the equivalent ``safelane reproduce``).
    ``nominal``: a registered nominal planner or a model file (``.npz``/``.onnx``) that the experiments run instead
    of the preset's network (the rule-based Table 1 still runs the preset's rule-based planner).
    ``workers``: local processes, or a :class:`~safelane.parallel.Backend` (``Backend("ray")``: a Ray cluster); the
    CSVs are byte-identical on every backend and worker count.
    With ``progress`` a Rich progress bar runs and the time of every experiment is printed.
    """
    from ..reporting.report import RunRecord, write_report

    preset_label = preset.name if isinstance(preset, Preset) else str(preset)
    preset = preset if isinstance(preset, Preset) else load_preset(preset)
    if nominal is not None:  # the experiments run this planner instead of the preset's network
        from ..planners.registry import load_nominal

        load_nominal(nominal)  # a bad name or file fails here, before any work
        preset = dataclasses.replace(preset, network=str(nominal))
    names = [get_experiment(n).name for n in (experiments or EXPERIMENTS)]
    configs = dict(configs or {})
    if set(configs) - set(names):
        raise ValueError(f"configs for experiments that do not run: {sorted(set(configs) - set(names))}")
    started = dt.datetime.now(dt.timezone.utc)
    run_dir = _new_run_dir(Path(out_dir or "results"), run_id(seed, quick, started))
    try:
        results = _run_all(names, configs, preset, seed, quick, workers, progress)
    except BaseException:
        # Interrupted (Ctrl-C) or failed before anything was written: leave no empty run folder behind.
        shutil.rmtree(run_dir, ignore_errors=True)
        raise

    t0 = time.perf_counter()
    files = write_files(results, run_dir, preset, workers)
    timings = {n: r.elapsed_s for n, r in results.items()}
    timings["figures and files"] = time.perf_counter() - t0
    record = RunRecord(
        run_id=run_dir.name,
        run_dir=run_dir,
        seed=seed,
        quick=quick,
        command=command or _equivalent_command(seed, quick, workers, preset_label, out_dir, configs),
        preset=preset,
        results=results,
        claims=files.claims,
        side_by_side=files.side_by_side,
        mae=files.mae,
        figures=files.figures,
        data_files=files.data_files,
        versions=software_versions(),
        parquet=_has_pyarrow(),
        timings=timings,
        started_utc=f"{started:%Y-%m-%d %H:%M:%S}",
    )
    write_report(record)
    _write_run_json(record)  # last: status "complete" once every file is written
    if progress:
        _console().print(f"report: {run_dir / 'report.html'} (total {sum(timings.values()):.1f} s)")
    return run_dir


def _console():
    from rich.console import Console

    return Console(stderr=True)


def _new_run_dir(base: Path, rid: str) -> Path:
    """``base/rid``, or ``base/rid-2``, ``-3``… when a run in the same second already took the name."""
    for k in range(1, 1000):
        path = base / (rid if k == 1 else f"{rid}-{k}")
        try:
            path.mkdir(parents=True)
        except FileExistsError:
            continue
        (path / "data").mkdir()
        return path
    raise RuntimeError(f"could not create a run folder under {base}")


def _run_all(names, configs, preset, seed, quick, workers, progress) -> dict[str, ExperimentResult]:
    """Run the experiments in order (sharing simulated cells), with a Rich progress bar and the time of each."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    results, cache = {}, {}
    columns = (SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn())
    with Progress(*columns, TimeElapsedColumn(), console=_console(), disable=not progress) as bar:
        task = bar.add_task("experiments", total=len(names))
        for name in names:
            bar.update(task, description=f"running {name}")
            res = run_experiment(
                name, configs.get(name), preset=preset, seed=seed, quick=quick, workers=workers, cache=cache
            )
            results[name] = res
            if progress:
                size = f"{len(res.summary)} cells, {len(res.table)} scenarios" if res.summary is not None else "trace"
                bar.console.print(f"{name:<16} {res.elapsed_s:7.2f} s  ({size})")
            bar.advance(task)
        bar.update(task, description="done")
    return results


@dataclass(frozen=True)
class RunFiles:
    """What :func:`write_files` wrote and computed: the data files (relative to the run folder, in a fixed order),
    the figures per experiment, the claims and Table 1 beside the paper's (``None`` without ``table1``)."""

    data_files: list[Path]
    figures: dict[str, list[Path]]
    claims: list
    side_by_side: pd.DataFrame | None
    mae: float | None


def write_files(
    results: Mapping[str, ExperimentResult], run_dir: Path, preset: Preset, workers: int | Backend = 1
) -> RunFiles:
    """Write the run's tables (``data/``) and figures (``figures/``) and check the claims: the report's "figures and
    files" step.

    Every table and figure is an independent job. With ``workers`` > 1 local processes they run on that many
    processes, the costliest first so that the processes finish close together; with one, or on Ray (whose nodes
    need not share this machine's disk), they run here, one after the other. The files are the same either way:
    each job writes its own files, and the CSVs are byte-identical to ``DataFrame.to_csv`` (:mod:`.csv_writer`).
    """
    parquet = _has_pyarrow()
    jobs: list[tuple] = []
    data_files: list[Path] = []
    for name, res in results.items():
        for kind, frame in (("scenarios", res.table), ("summary", res.summary), ("trace", res.trace)):
            if frame is None:
                continue
            rel = Path("data") / f"{name}_{kind}.csv"
            jobs.append(("table", frame, run_dir / rel, parquet))
            data_files += [rel, rel.with_suffix(".parquet")] if parquet else [rel]
    # The paper's claims are checked on the paper's conditions only (not on baselines run under other followers).
    summaries = {n: r.summary for n, r in results.items() if r.summary is not None and EXPERIMENTS[n].feeds_claims}
    fig5 = results["fig5_example"].trace if "fig5_example" in results else None
    claims = check_claims(summaries, fig5_trace=fig5)
    jobs.append(("table", pd.DataFrame([asdict(c) for c in claims]), run_dir / "data" / "claims.csv", False))
    data_files.append(Path("data/claims.csv"))
    side, mae = (None, None)
    if "table1" in summaries:
        side, mae = table1_side_by_side(summaries["table1"])
        jobs.append(("table", side, run_dir / "data" / "table1_side_by_side.csv", False))
        data_files.append(Path("data/table1_side_by_side.csv"))
    figure_jobs = {}  # experiment -> index of its figure's job
    drawable = _figure_names()
    for name, res in results.items():
        data = res.summary if res.summary is not None else res.trace
        if name in drawable and data is not None and len(data):
            figure_jobs[name] = len(jobs)
            jobs.append(("figure", name, data, run_dir / "figures", preset.params.y_boundary))
    be = as_backend(workers)
    local = (be.workers or 1) if be.name == "process" else 1
    order = sorted(range(len(jobs)), key=lambda k: -_job_cost(jobs[k]))
    if local > 1 and figure_jobs:
        from ..reporting.figures import import_plotting

        import_plotting()  # once here, not once in each worker
    # The workers are forks of this process: frozen, its objects (the simulations' heap) are left out of their
    # garbage collections, which would otherwise walk them all and copy the pages they touch. (Not where the caller
    # froze objects of its own: unfreezing would release them too.)
    freeze = local > 1 and gc.get_freeze_count() == 0
    if freeze:
        gc.freeze()
    try:
        done = map_chunks(_file_job, [jobs[k] for k in order], "process", workers=local)
    finally:
        if freeze:
            gc.unfreeze()
    written = dict(zip(order, done, strict=True))
    figures = {name: written[k] for name, k in figure_jobs.items()}
    return RunFiles(data_files, figures, claims, side, mae)


#: Rough cost of a job for the schedule: seconds per table cell, and per figure (measured on the full run).
_CELL_S, _FIGURE_S = 8e-8, 0.3


def _job_cost(job: tuple) -> float:
    return _CELL_S * job[1].size if job[0] == "table" else _FIGURE_S


def _figure_names() -> set[str]:
    from ..reporting.figures import FIGURES  # its names only: matplotlib is imported where a figure is drawn

    return set(FIGURES)


def _file_job(job: tuple) -> list[Path]:
    """One table (CSV, and Parquet when asked) or one figure; returns the paths written."""
    if job[0] == "table":
        _, frame, path, parquet = job
        write_csv(frame, path)
        if parquet:
            frame.to_parquet(path.with_suffix(".parquet"), index=False)
            return [path, path.with_suffix(".parquet")]
        return [path]
    from ..reporting.figures import FIGURES

    _, name, data, out, y_boundary = job
    return FIGURES[name](data, out, y_boundary)


def _has_pyarrow() -> bool:
    return importlib.util.find_spec("pyarrow") is not None


def software_versions() -> dict[str, str]:
    """Versions of Python, the numeric stack and safelane, and the platform."""
    from importlib.metadata import PackageNotFoundError, version

    import safelane

    out = {"python": platform.python_version(), "safelane": safelane.__version__}
    for pkg in ("numpy", "pandas", "matplotlib", "pydantic", "pyarrow"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "not installed"
    out["platform"] = platform.platform()
    return out


def _equivalent_command(seed, quick, workers, preset: str, out_dir, configs) -> str:
    parts = ["safelane", "reproduce", "--seed", str(seed)]
    parts += ["--quick"] if quick else []
    parts += as_backend(workers).cli_args()
    parts += ["--preset", preset] + (["--out", str(out_dir)] if out_dir else [])
    if configs:
        parts.append(f"(Python API, custom configs for {', '.join(sorted(configs))})")
    return " ".join(parts)


def _write_run_json(r) -> None:
    info = {
        "run_id": r.run_id,
        "kind": "reproduce",
        # The contract of every command's run folder (safelane.cli._runs); written after every other file.
        "status": "complete",
        "started_utc": r.started_utc,
        "finished_utc": f"{dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M:%S}",
        "seed": r.seed,
        "quick": r.quick,
        "command": r.command,
        "preset": {
            "name": r.preset.name,
            "source": getattr(r.preset, "source", None),
            "params": r.preset.params.model_dump(),
            "sim": r.preset.sim.model_dump(),
            "planner": dict(r.preset.planner),
            "network": r.preset.network,
        },
        "configs": {n: res.config.model_dump(mode="json") for n, res in r.results.items()},
        "versions": r.versions,
        "parquet": r.parquet,
        "timings_s": {k: round(v, 3) for k, v in r.timings.items()},
        "mae_published_cells": r.mae,
        "claims": {c.key: c.holds for c in r.claims},
    }
    (r.run_dir / "run.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
