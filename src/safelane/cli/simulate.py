"""``safelane simulate``: one experiment cell → summary table on screen, CSVs (and a trace plot) in a run folder."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import typer

from . import app
from ._backend import backend_option, ray_address_option, record, resolve_backend, session, workers_option


@app.command()
def simulate(
    planner: str = typer.Option(
        "CV_all", "--planner", "-p", help="Planner variant: CV_all, CV_follow, CV_none or No_agg_assess; RSS "
        "baselines: RSS, RSS_V2X, RSS_matched or RSS_V2X_matched (docs/rss.md)."
    ),
    leaders: int = typer.Option(5, "--leaders", "-n", help="Number N of connected leaders L1..LN."),
    decel: float = typer.Option(5.0, "--decel", "-d", help="Sudden deceleration a_x_N+1_d of L(N+1), in m/s²."),
    samples: int = typer.Option(1000, "--samples", "-s", help="Number of random scenarios."),
    seed: int = typer.Option(0, "--seed", help="Seed; the same cell and seed give the same numbers as the report."),
    p_v: float = typer.Option(0.0, "--p-v", help="Unexpected promise-violation probability per period, in [0, 1]."),
    params_file: Path = typer.Option(None, "--params", help="YAML/JSON file with Params fields."),
    preset: str = typer.Option(
        None, "--preset", help="A preset name (e.g. 'paper') or YAML path: its params, horizon, assessment, planner."
    ),
    nominal: str = typer.Option(
        None, "--nominal", help="Nominal planner: expert (with --preset: the preset's rule-based planner and "
        "gains), mlp, mlp_paper, teacher, or a model file PATH.npz (as 'safelane train' writes it) or PATH.onnx "
        "(default: the preset's — paper: mlp_paper, the network distilled from its rule-based planner — else "
        "expert). Another network than the preset's warns: the preset's numbers come from its own."
    ),
    assessment: str = typer.Option(
        None, "--assessment", help="'observed' (the real one; default), 'slow' (delayed, sometimes missed verdicts; "
        "the paper preset's) or 'truth' (F's true type)."
    ),
    out: Path = typer.Option(
        Path("results/simulate"), "--out", "-o", help="Parent folder; the run goes to OUT/<run-id>/ (created)."
    ),
    trace: bool = typer.Option(False, "--trace", help="Also write one scenario's trajectories (CSV) and a plot."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
    backend: str = backend_option(),
    workers: int = workers_option(),
    ray_address: str = ray_address_option(),
) -> None:
    """Simulate one cell of the paper's sampler and summarise it (rates with 95 % Wilson intervals).

    Writes OUT/<run-id>/ with scenarios.csv (one row per scenario), summary.csv and run.json (command, preset,
    planner, nominal planner, samples, assessment, seed, versions); run-id = UTC start time and the cell.

    With --trace also trace.csv and trace.png: the first scenario's lateral position and longitudinal speed.

    A cell (planner, N, decel, p_v) and seed give the same numbers here, in Python (safelane.simulate) and in
    the report of 'safelane reproduce' under the same preset.

    The printed summary names the preset and the nominal planner (the same cell differs between them).

    Example: safelane simulate --planner CV_all --leaders 5 --decel 5 --samples 1000 --seed 0
    Example: safelane simulate --preset paper --leaders 1 --decel 4   (the preset's network, mlp_paper)
    Example: safelane simulate --nominal results/train/RUN/model.npz   (a network from 'safelane train')

    Example: safelane simulate --samples 1000000 --backend ray   (the same numbers, on a Ray cluster)
    """
    from ..config import load_params
    from ..planners.registry import is_model_path
    from ..sim import SimConfig
    from ..sim import simulate as run
    from ..sim.inputs import check_cell_args, network_mismatch, nominal_label, preset_nominal
    from ..sim.preset import load_preset
    from ._runs import check_out_dir, preset_record, run_folder

    def bad(exc: Exception, option: str):
        return typer.BadParameter(str(exc), param_hint=option)

    if preset is not None and params_file is not None:
        raise typer.BadParameter("give either --preset or --params, not both", param_hint="--preset")
    try:
        chosen = load_preset(preset) if preset is not None else None
    except ValueError as exc:
        raise bad(exc, "--preset") from exc
    try:
        params = chosen.params if chosen else load_params(params_file)
    except ValueError as exc:
        raise bad(exc, "--params") from exc
    base = chosen.sim if chosen else SimConfig()
    if assessment is not None and assessment not in ("observed", "slow", "truth"):
        raise typer.BadParameter(f"{assessment!r} is not one of 'observed', 'slow', 'truth'", param_hint="--assessment")
    config = base.model_copy(update={"assessment": assessment or base.shield.assessment})
    try:
        with warnings.catch_warnings():  # said once below, as one line
            warnings.simplefilter("ignore", UserWarning)
            planner_obj = preset_nominal(chosen, nominal)
    except ValueError as exc:
        raise bad(exc, "--nominal") from exc
    mismatch = network_mismatch(chosen, nominal)
    if mismatch:
        typer.echo(f"Warning: {mismatch.replace('nominal / --nominal', '--nominal')}", err=True)
    options = {"planner": "--planner", "n_leaders": "--leaders", "decel": "--decel", "samples": "--samples",
               "seed": "--seed", "p_v": "--p-v"}
    try:
        check_cell_args(planner, leaders, decel, samples, seed, p_v)
    except ValueError as exc:  # InputError names the argument; an unknown variant comes from the registry
        raise bad(exc, options.get(getattr(exc, "where", None) or "", "--planner")) from exc
    where = resolve_backend(backend, workers, ray_address)
    out = check_out_dir(out)

    label = f"{planner}_N{leaders}_decel{decel:g}_pv{p_v:g}_seed{seed}"
    nominal_tag = Path(nominal).stem if nominal and is_model_path(nominal) else nominal  # a model file: its name
    label += "".join(f"-{re.sub(r'[^A-Za-z0-9_.]+', '_', part)}" for part in (chosen and chosen.name, nominal_tag)
                     if part)  # fmt: skip
    info = {
        "kind": "simulate",
        "preset": preset_record(chosen),
        "params_file": None if params_file is None else str(params_file),
        "planner": planner,
        "nominal": nominal_label(chosen, nominal),
        "n_leaders": leaders,
        "decel": decel,
        "p_v": p_v,
        "samples": samples,
        "seed": seed,
        "assessment": config.shield.assessment,
        "params": params.model_dump(),
        "sim": config.model_dump(),
        **record(where),
    }
    with session(where), run_folder(out, label, info) as (run_dir, info):
        result = run(planner, leaders, decel, samples, seed, p_v=p_v, params=params, config=config, trace=trace,
                     progress=progress, nominal=planner_obj, workers=where)  # fmt: skip
        result.preset, result.nominal = chosen and chosen.name, info["nominal"]  # summary.csv names them
        table, summary = result.table, result.summary()
        written = [run_dir / "scenarios.csv", run_dir / "summary.csv"]
        table.to_csv(written[0], index=False)
        summary.to_csv(written[1], index=False)
        if trace and result.trace is not None:
            from ..reporting.trace import plot_trace

            first = result.trace[result.trace["scenario_id"] == table["scenario_id"].iloc[0]]
            written.append(run_dir / "trace.csv")
            first.to_csv(written[-1], index=False)
            scenario = int(first["scenario_id"].iloc[0])
            title = f"{planner}, N = {leaders}, $a_{{x,N+1,d}}$ = {decel:g} m/s², scenario {scenario}"
            png = run_dir / "trace.png"
            written.append(
                plot_trace(first, png, y_boundary=params.y_boundary, lane_width=params.lane_width, title=title)
            )
        info["files"] = [p.name for p in written] + ["run.json"]
        info["success_rate"] = float(table["success"].mean())
        info["collision_rate"] = float(table["collision"].mean())
    _print_summary(table, planner, leaders, decel, samples, seed, p_v, config.shield.assessment,
                   chosen.name if chosen else None, info["nominal"])  # fmt: skip
    for path in written:
        typer.echo(f"wrote {path}")
    typer.echo(f"run folder: {run_dir}")


def _print_summary(table, planner, leaders, decel, samples, seed, p_v, assessment, preset, nominal) -> None:
    from rich.console import Console

    from ._runs import outcome_table

    title = (f"{planner}, N = {leaders}, a_x_N+1_d = {decel:g} m/s², p_v = {p_v:g}, {samples} scenarios, seed {seed}"
             f", assessment {assessment}, preset {preset or 'none (defaults)'}, nominal planner {nominal}")  # fmt: skip
    rows = (
        ("success", "success"),
        ("collision", "collision"),
        ("safety-distance violation", "safety_violation"),
        ("leader collision", "leader_collision"),
        ("leader margin violation", "leader_violation"),
        ("assessment correct", "assessment_correct"),
    )
    Console().print(outcome_table(title, table, rows))
