"""``safelane sumo``: one experiment cell in SUMO (libsumo) → summary on screen, CSVs in a run folder.

The cell's scenarios are ``safelane simulate``'s (the same seed gives the same initial states), run with the same
planner variant, nominal planner (``--nominal``; default the expert, as ``SumoRunner()``:
``integrations.sumo.DEFAULT_NOMINAL``) and shield settings; SUMO integrates the vehicles and its own collision
list is the referee (docs/integrations.md, SUMO).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import typer

from . import app

TRAFFIC_HELP = ("Who drives F and the connected leaders: 'paper' (safelane's models inside SUMO, the shield's "
                "assumptions) or 'sumo' (SUMO's own Krauss drivers, who promised nothing).")  # fmt: skip


@app.command()
def sumo(
    leaders: int = typer.Option(5, "--leaders", "-n", help="Number N of connected leaders L1..LN."),
    decel: float = typer.Option(5.0, "--decel", "-d", help="Sudden deceleration a_x_N+1_d of L(N+1), in m/s²."),
    episodes: int = typer.Option(100, "--episodes", "-e", help="Number of episodes (the sampler's scenarios)."),
    traffic: str = typer.Option("paper", "--traffic", help=TRAFFIC_HELP),
    planner: str = typer.Option(
        "CV_all", "--planner", "-p", help="Planner variant: CV_all, CV_follow, CV_none, No_agg_assess, RSS, ..."
    ),
    seed: int = typer.Option(0, "--seed", help="Seed; the same cell and seed give 'safelane simulate's scenarios."),
    shield: bool = typer.Option(True, "--shield/--no-shield", help="--no-shield runs the nominal planner alone."),
    nominal: str = typer.Option(
        None, "--nominal", help="Nominal planner: expert (default, as SumoRunner() in Python), mlp, mlp_paper, "
        "teacher, or a model file PATH.npz (as 'safelane train' writes it) or PATH.onnx."
    ),
    gui: bool = typer.Option(False, "--gui", help="Run in sumo-gui through TraCI (needs eclipse-sumo; one process)."),
    fcd: Path = typer.Option(
        None, "--fcd", help="SUMO's floating-car data: this file for one episode, else FILE-<scenario id>.xml each."
    ),
    out: Path = typer.Option(
        Path("results/sumo"), "--out", "-o", help="Parent folder; the run goes to OUT/<run-id>/ (created)."
    ),
    workers: int = typer.Option(1, "--workers", min=1, help="Processes, one SUMO each (libsumo: one per process)."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Run one cell of the paper's sampler in SUMO and summarise it (rates with 95 % Wilson intervals).

    Writes OUT/<run-id>/ with scenarios.csv (one row per episode: the columns of 'safelane simulate' that apply,
    collisions by SUMO's list, then SUMO's own columns), collisions.csv (SUMO's collision list: every entry, with
    the time and the ego's lateral phase), summary.csv and run.json.

    Example: safelane sumo --leaders 5 --decel 5 --episodes 100

    Example: safelane sumo --leaders 3 --decel 6 --episodes 200 --traffic sumo --workers 2

    Example: safelane sumo --nominal results/train/RUN/model.npz   (a network from 'safelane train')
    """
    from ..integrations.sumo import DEFAULT_NOMINAL, TRAFFIC_MODES
    from ..sim.inputs import as_nominal, check_cell_args
    from ._runs import check_out_dir

    if traffic not in TRAFFIC_MODES:
        raise typer.BadParameter(f"{traffic!r} is not one of {', '.join(map(repr, TRAFFIC_MODES))}",
                                 param_hint="--traffic")  # fmt: skip
    options = {"planner": "--planner", "n_leaders": "--leaders", "decel": "--decel", "samples": "--episodes",
               "seed": "--seed"}  # fmt: skip
    try:
        check_cell_args(planner, leaders, decel, episodes, seed, 0.0)
    except ValueError as exc:
        where = getattr(exc, "where", None) or ""
        message = str(exc).replace("samples must", "episodes must") if where == "samples" else str(exc)
        raise typer.BadParameter(message, param_hint=options.get(where, "--planner")) from exc
    try:
        as_nominal(nominal or DEFAULT_NOMINAL)  # fail before any work; each SUMO process loads it again
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--nominal") from exc
    nominal = nominal or DEFAULT_NOMINAL
    if gui and workers > 1:
        raise typer.BadParameter(f"--gui runs in one process; got --workers {workers}", param_hint="--workers")
    if fcd is not None:
        if fcd.is_dir():
            raise typer.BadParameter(f"{str(fcd)!r} is a folder; expected a file name (e.g. fcd.xml)",
                                     param_hint="--fcd")  # fmt: skip
        check_out_dir(fcd.parent if str(fcd.parent) else Path("."), "--fcd")
    _require_sumo(gui)
    out = check_out_dir(out)
    _run(leaders, decel, episodes, traffic, planner, seed, shield, gui, fcd, out, workers, progress, nominal)


def _require_sumo(gui: bool) -> None:
    """libsumo (or, for --gui, TraCI and sumo-gui) importable, else one line with the install hint, exit 2."""
    from ..integrations.sumo_world import INSTALL_HINT, libsumo_available

    problem = None
    if not libsumo_available():
        problem = INSTALL_HINT
    elif gui and _gui_binary() is None:
        problem = "--gui needs sumo-gui and TraCI: pip install eclipse-sumo (or put SUMO's bin/ on PATH)"
    if problem:
        typer.echo(f"Error: {problem}", err=True)
        raise typer.Exit(code=2)


def _gui_binary() -> str | None:
    try:
        import sumo as eclipse_sumo  # eclipse-sumo

        path = Path(eclipse_sumo.SUMO_HOME) / "bin" / "sumo-gui"
        if path.exists():
            return str(path)
    except ImportError:
        pass
    return shutil.which("sumo-gui")


def _run(leaders, decel, episodes, traffic, planner, seed, shielded, gui, fcd, out, workers, progress,
         nominal) -> None:  # fmt: skip
    import time
    from importlib.metadata import version

    import pandas as pd

    from ..integrations.sumo import DEFAULT_NOMINAL
    from ..integrations.sumo_cells import cell_scenarios, fcd_path, run_episodes
    from ..integrations.sumo_world import net_file, sumo_args
    from ..params import Params
    from ..planners.registry import is_model_path
    from ..sim import SimConfig
    from ._runs import run_folder

    label = f"{planner}_N{leaders}_decel{decel:g}_{traffic}_seed{seed}" + ("" if shielded else "_noshield")
    if nominal != DEFAULT_NOMINAL:  # as simulate's: the name, or a model file's name
        label += "-" + (Path(nominal).stem if is_model_path(nominal) else nominal)
    label = re.sub(r"[^A-Za-z0-9_.-]+", "_", label)
    params = Params()
    info = {
        "kind": "sumo",
        "planner": planner,
        "nominal": nominal,
        "n_leaders": leaders,
        "decel": decel,
        "episodes": episodes,
        "seed": seed,
        "traffic": traffic,
        "shielded": shielded,
        "workers": workers,
        "gui": gui,
        "fcd": None if fcd is None else str(fcd),
        "libsumo": version("libsumo"),
        "sumo_args": sumo_args(
            net_file(), Path("<episode>.rou.xml"), params, lateral_resolution=0.25, fcd=None, seed=seed
        ),
        "params": params.model_dump(),
        "sim": SimConfig().model_dump(),
    }
    with run_folder(out, label, info) as (run_dir, info):
        _, scenarios = cell_scenarios(planner, leaders, decel, episodes, seed)
        t0 = time.perf_counter()
        results = run_episodes(scenarios, planner=planner, traffic=traffic, seed=seed, shielded=shielded,
                               workers=workers, gui=gui, fcd=fcd, progress=progress, nominal=nominal)  # fmt: skip
        wall = time.perf_counter() - t0
        table = pd.DataFrame([r.results_row(planner) for r in results])
        collisions = pd.DataFrame(
            [{"scenario_id": r.scenario_id, **c} for r in results for c in r.collisions],
            columns=["scenario_id", "collider", "victim", "type", "lane", "pos", "t", "phase", "ego_y"],
        )
        summary = _summary(table)
        written = [run_dir / name for name in ("scenarios.csv", "collisions.csv", "summary.csv")]
        table.to_csv(written[0], index=False)
        collisions.to_csv(written[1], index=False)
        summary.to_csv(written[2], index=False)
        info["files"] = [p.name for p in written] + ["run.json"]
        info["success_rate"] = float(table["success"].mean())
        info["collision_rate"] = float(table["collision"].mean())
        info["sumo_collisions"] = len(collisions)
        info["wall_s"] = round(wall, 2)
        info["episodes_per_s"] = round(episodes / wall, 3)
    _print_summary(table, len(collisions), planner, leaders, decel, episodes, seed, traffic, shielded, wall, workers,
                   nominal)  # fmt: skip
    for path in written:
        typer.echo(f"wrote {path}")
    if fcd is not None:
        typer.echo(f"floating-car data: {fcd_path(fcd, '<scenario id>', episodes)}")
    typer.echo(f"run folder: {run_dir}")


RATES = (
    ("success", "success"),
    ("collision (ego, SUMO's list)", "collision"),
    ("leader collision (SUMO's list)", "leader_collision"),
    ("geometric overlap (our cross-check)", "geometric_overlap"),
    ("assumption breach (monitor)", "assumption_breach"),
    ("assessment correct", "assessment_correct"),
)


def _summary(table):
    """One row: counts, rates and 95 % Wilson intervals of the outcome columns."""
    import pandas as pd

    from ..sim import wilson_interval

    n = len(table)
    row = {"planner": table["planner"].iloc[0], "n_leaders": int(table["n_leaders"].iloc[0]),
           "decel": float(table["decel"].iloc[0]), "traffic": table["traffic"].iloc[0], "samples": n}  # fmt: skip
    for _, col in RATES:
        k = int(table[col].sum())
        lo, hi = wilson_interval(k, n)
        row.update({f"{col}_rate": k / n, f"{col}_lo": float(lo), f"{col}_hi": float(hi)})
    row["mean_completion_time_s"] = table["completion_time_s"].mean()
    row["promise_violations"] = int(table["promise_violations"].sum())
    return pd.DataFrame([row])


def _print_summary(table, n_list, planner, leaders, decel, episodes, seed, traffic, shielded, wall, workers,
                   nominal) -> None:  # fmt: skip
    from rich.console import Console

    from ._runs import outcome_table

    n = len(table)
    title = (f"SUMO, {planner}{'' if shielded else ' without the shield'}, N = {leaders}, a_x_N+1_d = {decel:g} m/s²,"
             f" traffic {traffic}, {episodes} episodes, seed {seed}, nominal {nominal}")  # fmt: skip
    t = outcome_table(title, table, RATES, unit="episode")
    t.add_row("entries in SUMO's collision list", str(n_list), "", "")
    t.add_row("promise-violating periods", str(int(table["promise_violations"].sum())), "", "")
    t.add_row("episodes / s", f"{n / wall:.2f}", f"{workers} process(es)", "")
    Console().print(t)
