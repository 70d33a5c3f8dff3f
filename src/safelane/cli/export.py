"""``safelane export-onnx``: a trained ``.npz`` planner → ONNX (needs ``onnx``: ``pip install safelane[train]``)."""

from __future__ import annotations

from pathlib import Path

import typer

from . import app


@app.command("export-onnx")
def export_onnx(
    model: Path = typer.Argument(None, help="A model.npz written by 'safelane train'; default the shipped planner."),
    out: Path = typer.Option(..., "--out", "-o", help="The .onnx file to write (its folder is created)."),
) -> None:
    """Export a trained planner to ONNX (normalisation and output scaling included).

    Example: safelane export-onnx results/mlp/<run-id>/model.npz --out model.onnx
    """
    import zipfile

    from ..errors import one_line
    from ..planners.nn import MLPPlanner, load_default_planner
    from ._runs import check_out_dir

    if out.suffix != ".onnx":
        raise typer.BadParameter(f"{str(out)!r} must end in .onnx", param_hint="--out")
    if out.is_dir():
        raise typer.BadParameter(f"{str(out)!r} is a folder; give the path of the .onnx file", param_hint="--out")
    if model is not None and model.is_dir():
        raise typer.BadParameter(f"{str(model)!r} is a folder; give a model.npz file (safelane train writes one in its "
                                 "run folder)", param_hint="MODEL")  # fmt: skip
    try:
        planner = load_default_planner() if model is None else MLPPlanner.load(model)
    except (ValueError, FileNotFoundError) as exc:
        raise typer.BadParameter(str(exc), param_hint="MODEL") from exc
    except (EOFError, OSError, KeyError, zipfile.BadZipFile) as exc:  # empty, truncated or not a zip archive
        why = "the file is empty" if model.is_file() and model.stat().st_size == 0 else one_line(str(exc))
        raise typer.BadParameter(f"{str(model)!r} is not a readable .npz model file written by 'safelane train' "
                                 f"({why or type(exc).__name__})", param_hint="MODEL") from exc
    check_out_dir(out.parent if str(out.parent) else Path("."), "--out")
    try:
        written = planner.to_onnx(out)
    except ImportError as exc:
        typer.echo(f"Error: {exc}", err=True)
        raise typer.Exit(code=1) from exc
    typer.echo(f"wrote {written}")
