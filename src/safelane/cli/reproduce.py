"""``safelane reproduce``: run every experiment and write figures, tables and the report."""

from __future__ import annotations

from pathlib import Path

import typer

from . import app
from ._backend import backend_option, ray_address_option, resolve_backend, session, workers_option


@app.command()
def reproduce(
    quick: bool = typer.Option(False, "--quick", help="Reduced grid: the same code on fewer samples, in seconds."),
    seed: int = typer.Option(
        0, "--seed", min=0, help="Seed of every random draw; the same seed reproduces every number."
    ),
    out: Path = typer.Option(Path("results"), "--out", "-o", help="Parent folder; the run goes to OUT/<run-id>/."),
    backend: str = backend_option(),
    workers: int = workers_option(),
    ray_address: str = ray_address_option(),
    preset: str = typer.Option("paper", "--preset", help="Preset name (safelane/presets/NAME.yaml) or a YAML path."),
    only: list[str] = typer.Option(None, "--only", help="Run only this experiment (repeatable); default all."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show progress and per-experiment times."),
    nominal: str = typer.Option(
        None, "--nominal", help="Run this nominal planner instead of the preset's network: a registered name or a "
        "model file (PATH.npz from safelane train, PATH.onnx from export-onnx)."
    ),
) -> None:
    """Reproduce the paper: run every experiment, write CSVs, figures and the report.

    Writes tidy CSVs, PNG/SVG figures (paper Figs. 4-6, Table 1, and ours) and report.md/report.html.

    The run goes to OUT/<run-id>/, run-id = UTC start time, seed and grid (quick or full).

    The same seed reproduces every number in the CSVs.

    The CSVs are byte-identical on every --backend and --workers (docs/scale.md).

    Example: safelane reproduce --quick --seed 0 --out results

    Example: safelane reproduce --backend ray --ray-address HEAD_HOST:6379
    """
    from ..experiments.registry import get_experiment
    from ..experiments.reproduce import reproduce as run
    from ..sim.preset import load_preset
    from ._runs import check_out_dir, command_line, say

    command = command_line()
    try:
        load_preset(preset)  # fail before any work
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--preset") from exc
    if nominal is not None:
        from ..planners.registry import load_nominal

        try:
            load_nominal(nominal)
        except ValueError as exc:
            raise typer.BadParameter(str(exc), param_hint="--nominal") from exc
    for name in only or ():
        try:
            get_experiment(name)
        except ValueError as exc:
            raise typer.BadParameter(str(exc), param_hint="--only") from exc
    where = resolve_backend(backend, workers, ray_address)
    out = check_out_dir(out)
    before = set(out.iterdir())
    try:
        with session(where):
            run_dir = run(
                out,
                seed=seed,
                quick=quick,
                workers=where,
                preset=preset,
                progress=progress,
                experiments=only or None,
                command=command,
                nominal=nominal,
            )
    except KeyboardInterrupt:
        left = sorted(set(out.iterdir()) - before)
        say("interrupted: " + (f"kept the partial run folder {left[0]} (no run.json: not complete)" if left else
                               "the experiments had not finished; nothing was kept (the run folder is removed)"))
        raise
    typer.echo(str(run_dir / "report.html"))
