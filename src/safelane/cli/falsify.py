"""``safelane falsify``: search behaviours inside the paper's assumptions for a collision or a ``p_m`` violation."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from . import app
from ._backend import backend_option, ray_address_option, resolve_backend, session, workers_option


@app.command()
def falsify(
    minutes: float = typer.Option(1.0, "--minutes", "-m", min=0.0, help="Run at least this long [min]."),
    scenarios: int = typer.Option(10_000, "--scenarios", "-n", min=0, help="Simulate at least this many scenarios."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every draw; with --minutes 0 the report repeats."),
    method: str = typer.Option("all", "--method", help="random, cem (cross-entropy), knife (knife edges) or all."),
    batch_size: int = typer.Option(16384, "--batch-size", min=1, help="Scenarios generated per batch."),
    backend: str = backend_option(),
    workers: int = workers_option("Parallel search streams: processes, or Ray tasks (default: the cluster's CPUs)."),
    ray_address: str = ray_address_option(),
    world: str = typer.Option("paper", "--world", help="paper (the paper's assumptions), realistic (plus an "
                              "own-lane leader L0, sensing errors and actuation delay; docs/real_roads.md) or lanes "
                              "(four lanes, other vehicles changing lanes inside the world model's assumptions; "
                              "docs/falsification.md)."),
    others_decel: float = typer.Option(
        None, "--others-decel", help="The others' maximum braking a_o_d [m/s², >= 0] (RSS's brakeMax): every "
        "other vehicle may brake up to it and the search draws braking up to it; default a_x_d (the paper's)."
    ),
    out: Path = typer.Option(
        Path("results/falsify"), "--out", "-o", help="Parent folder; the run goes to OUT/<run-id>/ (created)."
    ),
    replay: Path = typer.Option(
        None, "--replay", help="Re-simulate one dumped scenario: a JSON from a run folder, or the folder (its "
        "worst.json)."
    ),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Adversarial falsification of the safety guarantee (docs/falsification.md).

    Searches initial states at the edges, L(N+1) acceleration profiles, leaders' tasks inside their promises,
    F inside its type's range and adversarial nominal planners, with random search, a cross-entropy optimiser
    and knife-edge families. Runs until both --minutes and --scenarios are reached, then prints the report and
    writes the run folder OUT/<run-id>/ (run-id = UTC start time, world, method and seed): report.json,
    worst.json (the scenario with the smallest gap over p_m), failure_<i>.json for each collision or violation
    found and breach_<i>.json for each scenario in which the monitor flagged a breach (replay with --replay), and
    run.json. Ctrl-C keeps the report of what was simulated so far.

    Example: safelane falsify --minutes 10 --scenarios 1000000 --seed 0 --out results/falsify

    Example: safelane falsify --replay results/falsify/<run-id>/worst.json

    Example: safelane falsify --backend ray --workers 64 --minutes 30 --scenarios 100000000   (docs/scale.md)
    """
    from ..experiments import falsify as fz

    if replay is not None:
        outcome = fz.replay(_read_dump(replay))
        if outcome.empty:
            typer.echo("not simulated: the scenario does not start inside the assumptions (the shield's initial "
                       "check finds no safe evasion)")  # fmt: skip
            return
        row = outcome.drop(columns="row").iloc[0]
        typer.echo("\n".join(f"{k}: {fz.json_scalar(v)!r}" for k, v in row.items()))
        return
    if not math.isfinite(minutes):
        raise typer.BadParameter(f"must be a finite number of minutes >= 0; got {minutes}", param_hint="--minutes")
    if world == "lanes":
        _lanes(minutes, scenarios, seed, min(batch_size, 4096), workers, others_decel, out)
        return
    if world not in fz.space.WORLDS:
        raise typer.BadParameter(f"must be one of {', '.join((*fz.space.WORLDS, 'lanes'))}; got {world!r}",
                                 param_hint="--world")  # fmt: skip
    if method not in (*fz.METHODS, "all"):
        raise typer.BadParameter(
            f"must be one of {', '.join((*fz.METHODS, 'all'))}; got {method!r}", param_hint="--method"
        )
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from ._backend import record
    from ._runs import check_out_dir, run_folder, say

    params = _params(others_decel)
    where = resolve_backend(backend, workers, ray_address)
    out = check_out_dir(out)  # before minutes of search, not after
    info = {"kind": "falsify", "world": world, "method": method, "scenarios": scenarios, "minutes": minutes,
            "seed": seed, "batch_size": batch_size, "others_decel": params.others_decel, **record(where)}
    columns = (TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[status]}"), TimeElapsedColumn())
    latest: list[fz.Report] = []
    with session(where), run_folder(out, f"falsify-{world}-{method}-seed{seed}", info) as (run_dir, info):
        bar = Progress(*columns, console=Console(stderr=True), disable=not progress, transient=True)
        try:
            with bar:
                task = bar.add_task("falsifying", total=max(scenarios, 1), status="")

                def on_batch(report: fz.Report) -> None:
                    latest[:] = [report]
                    failures = sum(report.counts[name] for name in fz.OUTCOMES)
                    status = f"{report.simulated:,} simulated, min gap/p_m {report.min_ratio:.12f}, failures {failures}"
                    bar.update(task, completed=min(report.simulated, scenarios), status=status)

                make = fz.Setting.realistic if world == "realistic" else fz.Setting
                setting = make(seed=seed, params=params)
                report = fz.falsify(scenarios, minutes, seed, method, batch_size=batch_size, on_batch=on_batch,
                                    workers=where, setting=setting)  # fmt: skip
        except KeyboardInterrupt:
            if latest:  # the report of the batches simulated so far: worth keeping after minutes of search
                _write(latest[0], run_dir, info)
                say(f"interrupted after {latest[0].simulated:,} simulated scenarios: their report is kept")
            raise
        written = _write(report, run_dir, info)
    typer.echo(report.text())
    typer.echo(f"wrote {written[0]}" + (f" and {len(written) - 1} scenario dumps" if len(written) > 1 else ""))
    typer.echo(f"run folder: {run_dir}")


def _lanes(minutes, scenarios, seed, batch_size, workers, others_decel, out: Path) -> None:
    """``--world lanes``: the multi-lane falsifier (:mod:`safelane.experiments.falsify_lanes`), its report printed and
    written as OUT/<run-id>/report.json."""
    import json

    from ..experiments.falsify_lanes import LaneWorld
    from ..experiments.falsify_lanes_run import run_streams
    from ._runs import check_out_dir, run_folder

    params = _params(others_decel)
    out = check_out_dir(out)
    info = {"kind": "falsify", "world": "lanes", "scenarios": scenarios, "minutes": minutes, "seed": seed,
            "batch_size": batch_size, "workers": workers or 1, "others_decel": params.others_decel}  # fmt: skip
    with run_folder(out, f"falsify-lanes-seed{seed}", info) as (run_dir, info):
        report = run_streams(scenarios, seed, batch_size, LaneWorld(params=params), minutes, workers or 1)
        summary = {"scenarios": report.generated, "not_started": report.not_started, "seconds": report.seconds,
                   **report.counts,
                   "min_ratio_inside": report.min_ratio_inside, "failures_inside": report.failures}  # fmt: skip
        (run_dir / "report.json").write_text(json.dumps(summary, indent=1))
        info["files"] = ["report.json", "run.json"]
    typer.echo(report.text())
    typer.echo(f"run folder: {run_dir}")


def _params(others_decel: float | None):
    """The limits of the search's world: ``Params()`` with the others' maximum braking ``--others-decel``; a bad value
    is a :class:`typer.BadParameter` naming the option and the range."""
    from ..params import Params

    if others_decel is None:
        return Params()
    try:
        return Params(a_o_d=others_decel)
    except ValueError as exc:
        why = exc.errors()[0]["msg"] if hasattr(exc, "errors") else str(exc)
        raise typer.BadParameter(f"{why}; got {others_decel}", param_hint="--others-decel") from exc


def _write(report, run_dir: Path, info: dict) -> list[Path]:
    """The report and dumps into the run folder; the counts into ``run.json``."""
    written = report.write(run_dir)
    summary = report.summary()
    info["scenarios_simulated"] = summary["scenarios_simulated"]
    info["failures"] = {k: summary[k] for k in ("collisions", "p_m_violations_ego", "leader_collisions",
                                                 "p_m_violations_leaders")}  # fmt: skip
    info["files"] = [p.name for p in written] + ["run.json"]
    return written


_DUMP = "give a scenario dump of a falsify run folder (worst.json, failure_<i>.json or breach_<i>.json)"


def _read_dump(path: Path) -> dict:
    """A scenario dump for ``--replay`` (a folder: its ``worst.json``); :class:`typer.BadParameter` naming the file
    and what is wrong otherwise."""
    import json

    def bad(why: str) -> typer.BadParameter:
        return typer.BadParameter(f"{str(path)!r}: {why}", param_hint="--replay")

    if path.is_dir():
        if not (path / "worst.json").is_file():
            raise bad(f"a folder without worst.json; {_DUMP}")
        path = path / "worst.json"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise bad(f"file not found; {_DUMP}") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise bad(f"cannot be read ({getattr(exc, 'strerror', None) or type(exc).__name__})") from exc
    try:
        record = json.loads(text)
    except json.JSONDecodeError as exc:
        raise bad(f"line {exc.lineno}, column {exc.colno}: invalid JSON: {exc.msg}") from exc
    keys = ("spec", "params", "sim", "seed", "decel_last_max", "use_hooks")
    missing = [k for k in keys if k not in record] if isinstance(record, dict) else list(keys)
    if missing:
        raise bad(f"not a falsify scenario dump (missing {', '.join(map(repr, missing))}); {_DUMP}")
    return record
