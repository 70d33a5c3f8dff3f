"""``safelane train``: train the neural planners from a YAML/JSON config (needs ``safelane[train]``)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from . import app


@app.command()
def train(
    config: Path = typer.Option(None, "--config", "-c", help="TrainConfig YAML/JSON; defaults when omitted."),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (created if missing)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show progress bars."),
) -> None:
    """Train the longitudinal and lateral networks: teacher-labelled states, DAgger, export, evaluation.

    Writes model.npz (load with MLPPlanner.load), model.onnx, metrics.csv, summary.json, config.yaml and,
    when the config has evaluation cells, closed_loop.csv. Unknown config keys are errors.

    Example: safelane train --config src/safelane/models/default_train.yaml --out results/mlp
    """
    from pydantic import ValidationError

    from ..training.train import TrainConfig
    from ..training.train import train as run

    try:
        cfg = TrainConfig.load(config)
    except (ValidationError, ValueError, FileNotFoundError) as exc:
        raise typer.BadParameter(str(exc), param_hint="--config") from exc
    try:
        result = run(cfg, out, progress=progress)
    except ImportError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from exc
    typer.echo(json.dumps({"out": str(result.out_dir), **result.summary}, indent=2))
