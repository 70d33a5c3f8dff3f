"""``safelane train``: train the neural planners from a YAML/JSON config (needs ``safelane[train]``)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from . import app


@app.command()
def train(
    config: Path = typer.Option(None, "--config", "-c", help="TrainConfig YAML/JSON; defaults when omitted."),
    out: Path = typer.Option(..., "--out", "-o", help="Parent folder; the run goes to OUT/<run-id>/ (created)."),
    progress: bool = typer.Option(
        True, "--progress/--no-progress", help="Progress bars, or (--no-progress) one line per stage on stderr."
    ),
) -> None:
    """Train the longitudinal and lateral networks: teacher-labelled states, DAgger, export, evaluation.

    Writes OUT/<run-id>/ with model.npz (load with MLPPlanner.load), model.onnx, model.json, metrics.csv,
    summary.json, config.yaml, run.json and, when the config has evaluation cells, closed_loop.csv.
    Unknown config keys are errors. The default config takes about 4 minutes on one core.

    Example: safelane train --config src/safelane/models/default_train.yaml --out results/mlp
    """
    from ..training.train import TrainConfig
    from ..training.train import train as run
    from ._runs import check_out_dir, run_folder

    try:
        cfg = TrainConfig.load(config)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--config") from exc
    try:
        from ..training.torch_model import require_torch  # imports torch: fails fast with the install hint

        require_torch()
    except ImportError as exc:
        typer.echo(f"Error: {exc}", err=True)
        raise typer.Exit(code=1) from exc
    out = check_out_dir(out)
    info = {"kind": "train", "config_file": None if config is None else str(config), "seed": cfg.seed,
            "threads": cfg.threads, "train_config_hash": cfg.config_hash()}
    with run_folder(out, f"train-seed{cfg.seed}", info) as (run_dir, info):
        result = run(cfg, run_dir, progress=progress)
        info["val_loss"] = result.summary.get("val_loss")
    typer.echo(json.dumps({"out": str(result.out_dir), **result.summary}, indent=2))
