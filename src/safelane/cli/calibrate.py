"""``safelane calibrate``: search the quantities the paper leaves open to match its published Table 1 rows."""

from __future__ import annotations

from pathlib import Path

import typer

from . import app


@app.command()
def calibrate(
    candidates: int = typer.Option(32, "--candidates", min=1, help="Latin-hypercube points of the first stage."),
    samples: int = typer.Option(100, "--samples", min=1, help="Scenarios per Table 1 cell in the first stage."),
    refine: int = typer.Option(16, "--refine", min=0, help="Local refinement steps around the best candidate."),
    finalists: int = typer.Option(4, "--finalists", min=1, help="Best candidates re-scored in the second stage."),
    final_samples: int = typer.Option(400, "--final-samples", min=1, help="Scenarios per cell when re-scoring."),
    seed: int = typer.Option(0, "--seed", help="Seed of the search and of every simulation."),
    out: Path = typer.Option(Path("results/calibration"), "--out", "-o", help="Folder for the preset and tables."),
    workers: int = typer.Option(1, "--workers", min=1, help="Processes per simulation batch."),
    install: bool = typer.Option(False, "--install", help="Also write the result as the package's 'paper' preset."),
) -> None:
    """Calibrate the 'paper' preset to the published N = 1 and N = 10 rows of Table 1.

    Searches accelerations, p_m, the horizon and planner gains over plausible ranges (N = 3 is never used).

    Loss: mean absolute success-rate difference over the 40 published cells; every candidate is shown.

    Writes OUT/paper.yaml, OUT/candidates.csv and OUT/fit_per_cell.csv; --install also PRESET_DIR/paper.yaml.

    Example: safelane calibrate --candidates 40 --refine 24 --finalists 4 --final-samples 400 --install
    """
    import pandas as pd
    from rich.console import Console

    from ..experiments.calibration import PRESET_DIR, SEARCH_SPACE
    from ..experiments.calibration import calibrate as run

    console = Console()
    console.print("calibration candidates (loss: mean |ours - paper| over 40 cells; * = best so far)")
    best = [float("inf")]

    def on_candidate(i: int, point: dict, loss: float) -> None:
        mark = " *" if loss < best[0] else "  "
        best[0] = min(best[0], loss)
        stage = "search" if i < candidates else "refine" if i < candidates + refine else "final"
        values = "  ".join(f"{k}={point[k]:.3g}" for k in SEARCH_SPACE)
        console.print(f"{i:4d} {stage:6s} loss {loss:.4f}{mark}  {values}", soft_wrap=True)

    preset, frame = run(
        candidates=candidates,
        samples=samples,
        refine=refine,
        finalists=min(finalists, candidates),
        final_samples=final_samples,
        seed=seed,
        on_candidate=on_candidate,
        workers=workers,
    )
    console.print()
    out.mkdir(parents=True, exist_ok=True)
    text = preset.to_yaml()
    (out / "paper.yaml").write_text(text, encoding="utf-8")
    frame.to_csv(out / "candidates.csv", index=False)
    pd.DataFrame(preset.meta.get("per_cell", [])).to_csv(out / "fit_per_cell.csv", index=False)
    console.print(f"chosen preset: loss {preset.meta.get('loss_mean_abs_diff')} (re-scored); wrote {out}/")
    if install:
        PRESET_DIR.mkdir(parents=True, exist_ok=True)
        (PRESET_DIR / "paper.yaml").write_text(text, encoding="utf-8")
        console.print(f"installed {PRESET_DIR / 'paper.yaml'}")
