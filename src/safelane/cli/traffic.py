"""``safelane traffic``: the traffic-level co-simulation in SUMO over penetration rates and demand levels → a run
folder with cells.csv, collisions.csv, report.md/html (docs/traffic.md)."""

from __future__ import annotations

from pathlib import Path

import typer

from . import app
from ._backend import backend_option, ray_address_option, workers_option


def _floats(text: str, option: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError as exc:
        raise typer.BadParameter(f"expected comma-separated numbers; got {text!r}", param_hint=option) from exc


@app.command()
def traffic(
    penetration: str = typer.Option("0,0.25,0.5,0.75,1", "--penetration", help="Penetration rates p, e.g. 0,0.5,1."),
    demand: str = typer.Option("4900", "--demand", help="Total demands [veh/h] (15 % on the ramp), e.g. 4000,4900."),
    seconds: float = typer.Option(3600.0, "--seconds", help="Simulated seconds per run (warm-up included)."),
    warmup: float = typer.Option(300.0, "--warmup", help="Warm-up [s] not measured."),
    seed: int = typer.Option(0, "--seed", help="Seed of the arrivals and of the penetration draw (shared by all)."),
    backend: str = backend_option(),
    workers: int = workers_option(),
    ray_address: str = ray_address_option(),
    out: Path = typer.Option(Path("results/traffic"), "--out", "-o", help="Parent folder: OUT/<run-id>/ (created)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Accepted for symmetry (one line per run)."),
    others: bool = typer.Option(False, "--others/--no-others", help="Feed the shield's world model: the vehicles in "
                                "the lane beyond the target and on the other side, with equipped changers' "
                                "lane-change announcements (docs/traffic.md)."),
    lc_duration: float = typer.Option(0.0, "--lc-duration", help="SUMO's --lanechange.duration [s] for its own "
                                      "drivers: 0 (SUMO's default) instantaneous lane changes, > 0 continuous ones."),
) -> None:  # fmt: skip
    """Run the merge network at every penetration × demand and write the measures and a report.

    Example: safelane traffic --penetration 0,0.5,1 --demand 4900 --seconds 600 --warmup 120 --workers 2
    """
    from ..integrations.sumo_world import INSTALL_HINT, libsumo_available
    from ..traffic.demand import Demand
    from . import _backend
    from ._runs import check_out_dir

    ps, qs = _floats(penetration, "--penetration"), _floats(demand, "--demand")
    if not ps or any(not 0.0 <= p <= 1.0 for p in ps):
        raise typer.BadParameter(f"every p must lie in [0, 1]; got {penetration!r}", param_hint="--penetration")
    if not qs or any(q <= 0 for q in qs):
        raise typer.BadParameter(f"every demand must be > 0 veh/h; got {demand!r}", param_hint="--demand")
    try:
        Demand(p=0.0, seconds=seconds, warmup_s=warmup, seed=seed)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--seconds") from exc
    if not (lc_duration >= 0.0 and lc_duration < float("inf")):
        raise typer.BadParameter(f"must be a finite number >= 0 s; got {lc_duration!r}", param_hint="--lc-duration")
    if not libsumo_available():
        typer.echo(f"Error: {INSTALL_HINT}", err=True)
        raise typer.Exit(code=2)
    where = _backend.resolve_backend(backend, workers, ray_address)
    out = check_out_dir(out)
    _run(ps, qs, seconds, warmup, seed, where, out, others, lc_duration)


def _run(ps, qs, seconds, warmup, seed, where, out, others=False, lc_duration=0.0) -> None:
    import time

    from ..parallel import as_backend
    from ..traffic import report
    from ..traffic.run import cells, sweep
    from . import _backend
    from ._runs import command_line, run_folder

    info = {"kind": "traffic", "penetration": ps, "demand_vph": qs, "seconds": seconds, "warmup_s": warmup,
            "seed": seed, "others": others, "lc_duration_s": lc_duration, **_backend.record(where)}  # fmt: skip
    label = f"traffic_seed{seed}"
    with run_folder(out, label, info) as (run_dir, info), _backend.session(where):
        jobs = cells(ps, qs, seconds=seconds, warmup_s=warmup, seed=seed, others=others, lc_duration_s=lc_duration)
        t0 = time.perf_counter()
        table, coll, walls = sweep(jobs, as_backend(where))
        wall = time.perf_counter() - t0
        table.to_csv(run_dir / "cells.csv", index=False)
        coll.to_csv(run_dir / "collisions.csv", index=False)
        md, page = report.write(run_dir, table, command_line())
        info["files"] = ["cells.csv", "collisions.csv", md.name, page.name, "figures", "run.json"]
        info["wall_s"] = round(wall, 2)
        info["job_wall_s"] = [round(w, 2) for w in walls]
    typer.echo(table.to_string(index=False))
    typer.echo(f"run folder: {run_dir}")
