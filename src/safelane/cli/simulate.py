"""``safelane simulate``: one experiment cell → summary table on screen, CSVs (and a trace plot) on disk."""

from __future__ import annotations

from pathlib import Path

import typer

from . import app


@app.command()
def simulate(
    planner: str = typer.Option("CV_all", "--planner", "-p", help="Planner variant: CV_all, CV_follow, CV_none, ..."),
    leaders: int = typer.Option(5, "--leaders", "-n", help="Number N of connected leaders L1..LN."),
    decel: float = typer.Option(5.0, "--decel", "-d", help="Sudden deceleration a_x_N+1_d of L(N+1), in m/s²."),
    samples: int = typer.Option(1000, "--samples", "-s", help="Number of random scenarios."),
    seed: int = typer.Option(0, "--seed", help="Seed of every random draw; the same seed gives the same table."),
    p_v: float = typer.Option(0.0, "--p-v", help="Unexpected promise-violation probability per period, in [0, 1]."),
    params_file: Path = typer.Option(None, "--params", help="YAML/JSON file with Params fields."),
    preset: str = typer.Option(
        None, "--preset", help="A calibrated preset (e.g. 'paper'): its params, horizon, assessment and planner."
    ),
    nominal: str = typer.Option(None, "--nominal", help="Nominal planner: expert (default), mlp or teacher."),
    assessment: str = typer.Option("observed", "--assessment", help="'observed' (the real one) or 'truth'."),
    out: Path = typer.Option(Path("results/simulate"), "--out", "-o", help="Output folder (created if missing)."),
    trace: bool = typer.Option(False, "--trace", help="Also write one scenario's trajectories (CSV) and a plot."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Simulate one cell of the paper's sampler and summarise it (rates with 95 % Wilson intervals).

    Writes STEM_scenarios.csv (one row per scenario) and STEM_summary.csv into OUT, with
    STEM = PLANNER_N<leaders>_decel<decel>_pv<p_v>_seed<seed>.

    With --trace also STEM_trace.csv and STEM_trace.png: the first scenario's lateral position and longitudinal
    speed over time.

    Example: safelane simulate --planner CV_all --leaders 5 --decel 5 --samples 1000 --seed 0
    Example: safelane simulate --preset paper --nominal mlp --leaders 1 --decel 4
    """
    from pydantic import ValidationError

    from ..config import load_params
    from ..experiments.calibration import load_preset
    from ..planners.registry import get_nominal
    from ..sim import SimConfig
    from ..sim import simulate as run

    if preset is not None and params_file is not None:
        raise typer.BadParameter("give either --preset or --params, not both", param_hint="--preset")
    try:
        chosen = load_preset(preset) if preset is not None else None
        params = chosen.params if chosen else load_params(params_file)
    except (ValidationError, ValueError, FileNotFoundError) as exc:
        raise typer.BadParameter(str(exc), param_hint="--preset" if preset else "--params") from exc
    try:
        config = (chosen.sim if chosen else SimConfig()).model_copy(update={"assessment": assessment})
        SimConfig.model_validate(config.model_dump())
    except ValidationError as exc:
        raise typer.BadParameter(str(exc), param_hint="--assessment") from exc
    try:
        planner_obj = get_nominal(nominal) if nominal else (chosen.nominal() if chosen else None)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--nominal") from exc
    try:
        result = run(planner, leaders, decel, samples, seed, p_v=p_v, params=params, config=config, trace=trace,
                     progress=progress, nominal=planner_obj)  # fmt: skip
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from exc

    stem = f"{planner}_N{leaders}_decel{decel:g}_pv{p_v:g}_seed{seed}"
    out.mkdir(parents=True, exist_ok=True)
    table, summary = result.table, result.summary()
    written = [out / f"{stem}_scenarios.csv", out / f"{stem}_summary.csv"]
    table.to_csv(written[0], index=False)
    summary.to_csv(written[1], index=False)
    if trace and result.trace is not None:
        from ..reporting.trace import plot_trace

        first = result.trace[result.trace["scenario_id"] == table["scenario_id"].iloc[0]]
        written.append(out / f"{stem}_trace.csv")
        first.to_csv(written[-1], index=False)
        scenario = int(first["scenario_id"].iloc[0])
        title = f"{planner}, N = {leaders}, $a_{{x,N+1,d}}$ = {decel:g} m/s², scenario {scenario}"
        png = out / f"{stem}_trace.png"
        written.append(plot_trace(first, png, y_boundary=params.y_boundary, lane_width=params.lane_width, title=title))
    _print_summary(table, planner, leaders, decel, samples, seed, p_v, assessment)
    for path in written:
        typer.echo(f"wrote {path}")


def _print_summary(table, planner, leaders, decel, samples, seed, p_v, assessment) -> None:
    from rich.console import Console
    from rich.table import Table

    from ..sim import wilson_interval

    n = len(table)
    t = Table(
        title=f"{planner}, N = {leaders}, a_x_N+1_d = {decel:g} m/s², p_v = {p_v:g}, {samples} scenarios, seed {seed}"
        f", assessment {assessment}"
    )
    for col, justify in (("outcome", "left"), ("count", "right"), ("rate", "right"), ("95 % Wilson interval", "right")):
        t.add_column(col, justify=justify)
    rows = (
        ("success", "success"),
        ("collision", "collision"),
        ("safety-distance violation", "safety_violation"),
        ("leader collision", "leader_collision"),
        ("leader margin violation", "leader_violation"),
        ("assessment correct", "assessment_correct"),
    )
    for label, col in rows:
        k = int(table[col].sum())
        lo, hi = wilson_interval(k, n)
        t.add_row(label, str(k), f"{k / n:.4f}", f"[{float(lo):.4f}, {float(hi):.4f}]")
    done = table["completion_time_s"].dropna()
    t.add_section()
    t.add_row("mean completion time", str(len(done)), f"{done.mean():.2f} s" if len(done) else "-", "")
    for label, col in (("hesitate steps / scenario", "n_hesitate"), ("abort steps / scenario", "n_abort")):
        t.add_row(label, str(int(table[col].sum())), f"{table[col].mean():.2f}", "")
    Console().print(t)
