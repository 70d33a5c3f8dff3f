"""``safelane falsify``: search behaviours inside the paper's assumptions for a collision or a ``p_m`` violation."""

from __future__ import annotations

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
    world: str = typer.Option("paper", "--world", help="paper (the paper's assumptions) or realistic (plus an "
                              "own-lane leader L0, sensing errors and actuation delay; docs/real_roads.md)."),
    out: Path = typer.Option(Path("results/falsify"), "--out", "-o", help="Folder for report.json and dumps."),
    replay: Path = typer.Option(None, "--replay", help="Re-simulate one dumped scenario (a JSON from --out)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Adversarial falsification of the safety guarantee (docs/falsification.md).

    Searches initial states at the edges, L(N+1) acceleration profiles, leaders' tasks inside their promises,
    F inside its type's range and adversarial nominal planners, with random search, a cross-entropy optimiser
    and knife-edge families. Runs until both --minutes and --scenarios are reached, then prints the report and
    writes OUT/report.json, OUT/worst.json (the scenario with the smallest gap over p_m) and OUT/failure_<i>.json
    for each collision or violation found (replay with --replay).

    Example: safelane falsify --minutes 10 --scenarios 1000000 --seed 0 --out results/falsify

    Example: safelane falsify --replay results/falsify/worst.json

    Example: safelane falsify --backend ray --workers 64 --minutes 30 --scenarios 100000000   (docs/scale.md)
    """
    from ..experiments import falsify as fz

    if replay is not None:
        outcome = fz.replay(replay)
        if outcome.empty:
            typer.echo("not simulated: the scenario does not start inside the assumptions (the shield's initial "
                       "check finds no safe evasion)")  # fmt: skip
            return
        row = outcome.drop(columns="row").iloc[0]
        typer.echo("\n".join(f"{k}: {fz.json_scalar(v)!r}" for k, v in row.items()))
        return
    if world not in fz.space.WORLDS:
        raise typer.BadParameter(f"must be one of {', '.join(fz.space.WORLDS)}; got {world!r}", param_hint="--world")
    if method not in (*fz.METHODS, "all"):
        raise typer.BadParameter(
            f"must be one of {', '.join((*fz.METHODS, 'all'))}; got {method!r}", param_hint="--method"
        )
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from ._runs import check_out_dir

    where = resolve_backend(backend, workers, ray_address)
    out = check_out_dir(out)  # before minutes of search, not after
    columns = (TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[status]}"), TimeElapsedColumn())
    with session(where), Progress(*columns, disable=not progress, transient=True) as bar:
        task = bar.add_task("falsifying", total=max(scenarios, 1), status="")

        def on_batch(report: fz.Report) -> None:
            failures = sum(report.counts[name] for name in fz.OUTCOMES)
            status = f"{report.simulated:,} simulated, min gap/p_m {report.min_ratio:.12f}, failures {failures}"
            bar.update(task, completed=min(report.simulated, scenarios), status=status)

        setting = fz.Setting.realistic(seed=seed) if world == "realistic" else None
        report = fz.falsify(scenarios, minutes, seed, method, batch_size=batch_size, on_batch=on_batch, workers=where,
                            setting=setting)  # fmt: skip
    typer.echo(report.text())
    written = report.write(out)
    typer.echo(f"wrote {written[0]}" + (f" and {len(written) - 1} scenario dumps" if len(written) > 1 else ""))
