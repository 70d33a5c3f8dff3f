"""``safelane calibrate``: search the quantities the paper leaves open to match its published Table 1 rows."""

from __future__ import annotations

import dataclasses
import re
import time
from pathlib import Path

import typer

from . import app
from ._backend import backend_option, ray_address_option, record, resolve_backend, session, workers_option


@app.command()
def calibrate(
    candidates: int = typer.Option(64, "--candidates", min=1, help="Latin-hypercube points of the first stage."),
    samples: int = typer.Option(100, "--samples", min=1, help="Scenarios per Table 1 cell in the first stage."),
    refine: int = typer.Option(32, "--refine", min=0, help="Local refinement steps around the best candidate."),
    finalists: int = typer.Option(4, "--finalists", min=1, help="Best candidates re-scored in the second stage."),
    final_samples: int = typer.Option(400, "--final-samples", min=1, help="Scenarios per cell when re-scoring."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the search and of every simulation."),
    out: Path = typer.Option(
        Path("results/calibration"), "--out", "-o", help="Parent folder; the run goes to OUT/<run-id>/."
    ),
    backend: str = backend_option(),
    workers: int = workers_option(),
    ray_address: str = ray_address_option(),
    install: bool = typer.Option(
        False, "--install", help="Also install the result as a user preset (see --name), outside the package."
    ),
    name: str = typer.Option(
        "calibrated", "--name", help="Name of the result (preset.yaml) and of the user preset --install writes "
        "(then --preset NAME): letters, digits, '-' or '_'."
    ),
    preset_dir: Path = typer.Option(
        None, "--preset-dir", help="Folder of user presets; default $SAFELANE_PRESET_DIR or ~/.config/safelane/presets."
    ),
) -> None:
    """Calibrate the quantities the paper leaves open to its published N = 1 and N = 10 rows of Table 1.

    Searches accelerations, p_m, the horizon and planner gains over plausible ranges (N = 3 is never used).
    The defaults are the settings that built the shipped 'paper_numbers' preset (its meta.command); the shipped
    'paper' preset comes from 'python -m safelane.experiments.structure' (its meta.history). Rather different
    parameter sets fit about equally well: read the result as one good choice, not a measurement.

    Loss: mean absolute success-rate difference over the 40 published cells; every candidate is shown, with
    the total and an estimate of the time left.

    Writes OUT/<run-id>/ with preset.yaml (named NAME), candidates.csv, fit_per_cell.csv and run.json. --install
    also writes the preset as a user preset NAME (never into the package): use it with --preset NAME. Ctrl-C
    keeps the candidates scored so far (candidates.csv, run.json status 'interrupted').

    Example: safelane calibrate --install --name mine   (then: safelane simulate --preset mine)

    Example: safelane calibrate --backend ray --ray-address HEAD_HOST:6379   (a cluster: docs/scale.md)
    """
    import pandas as pd
    from rich.console import Console

    from ..experiments.calibration import SEARCH_SPACE
    from ..experiments.calibration import calibrate as run
    from ..sim.preset import PRESET_DIR, install_preset, user_preset_dir
    from ._runs import check_out_dir, run_folder, say

    _check_name(name)  # before the calibration runs, not after
    if install and (PRESET_DIR / f"{name}.yaml").exists():
        raise typer.BadParameter(f"{name!r} is a shipped preset and cannot be replaced; choose another name",
                                 param_hint="--name")
    where = resolve_backend(backend, workers, ray_address)
    out = check_out_dir(out)
    target = preset_dir or user_preset_dir()
    if install:
        check_out_dir(target, "--preset-dir")
    console = Console()
    finalists = min(finalists, candidates)
    total = candidates + refine + finalists
    console.print(f"calibration: {total} candidates ({candidates} search, {refine} refine, {finalists} final); "
                  "loss: mean |ours - paper| over 40 cells; * = best so far", soft_wrap=True)
    best = [float("inf")]
    scored: list[dict] = []  # every candidate scored so far: kept on Ctrl-C
    start = time.perf_counter()

    def on_candidate(i: int, point: dict, loss: float) -> None:
        mark = " *" if loss < best[0] else "  "
        best[0] = min(best[0], loss)
        stage = "search" if i < candidates else "refine" if i < candidates + refine else "final"
        scored.append({**{k: point[k] for k in SEARCH_SPACE}, "loss": loss, "stage": 2 if stage == "final" else 1})
        values = "  ".join(f"{k}={point[k]:.3g}" for k in SEARCH_SPACE)
        elapsed = time.perf_counter() - start
        eta = elapsed / (i + 1) * (total - i - 1)
        console.print(f"{i + 1:4d}/{total} {stage:6s} loss {loss:.4f}{mark}  {values}  "
                      f"[{elapsed:.0f} s, ~{eta:.0f} s left]", soft_wrap=True, markup=False)

    args = {"candidates": candidates, "samples": samples, "refine": refine, "finalists": finalists,
            "final_samples": final_samples, "seed": seed, "workers": where}
    info = {"kind": "calibrate", "name": name, **args, **record(where)}
    with session(where), run_folder(out, f"calibrate-seed{seed}", info) as (run_dir, info):
        try:
            fitted, frame = run(**args, on_candidate=on_candidate)
        except KeyboardInterrupt:
            if scored:  # minutes of simulation each: keep them (the run folder is then kept, status interrupted)
                pd.DataFrame(scored).to_csv(run_dir / "candidates.csv", index=False)
                info["candidates_scored"] = len(scored)
                say(f"interrupted: kept the {len(scored)} candidates scored so far in {run_dir / 'candidates.csv'}")
            raise
        console.print()
        # The result carries the user's name, not the shipped preset's the search starts from.
        preset = dataclasses.replace(fitted, name=name)
        text = preset.to_yaml()
        (run_dir / "preset.yaml").write_text(text, encoding="utf-8")
        frame.to_csv(run_dir / "candidates.csv", index=False)
        pd.DataFrame(preset.meta.get("per_cell", [])).to_csv(run_dir / "fit_per_cell.csv", index=False)
        info["loss_mean_abs_diff"] = preset.meta.get("loss_mean_abs_diff")
        if install:
            path = install_preset(preset, name, target)
            info["installed"] = str(path)
    console.print(f"chosen preset: loss {preset.meta.get('loss_mean_abs_diff')} (re-scored); wrote {run_dir}/")
    if install:
        console.print(f"installed user preset {name!r}: {path} (use --preset {name})")


def _check_name(name: str) -> None:
    """``--name`` becomes a file name and a preset name: letters, digits, '-' or '_' only."""
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name or ""):
        raise typer.BadParameter(f"{name!r} is not a preset name; allowed: letters, digits, '-' or '_' (it becomes "
                                 "NAME.yaml in the user preset folder)", param_hint="--name")  # fmt: skip
