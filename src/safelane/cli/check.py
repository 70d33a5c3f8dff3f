"""``safelane check``: one state → verdict and evasion plan as JSON."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from . import app


@app.command()
def check(
    ego_px: float = typer.Option(0.0, help="Ego longitudinal position [m]."),
    ego_py: float = typer.Option(1.2, help="Ego lateral centre position [m] (original lane centre = 0)."),
    ego_vx: float = typer.Option(30.0, help="Ego speed [m/s]."),
    ego_vy: float = typer.Option(0.5, help="Ego lateral speed [m/s], positive toward the target lane."),
    l1_p: float = typer.Option(20.0, help="L1 position [m]."),
    l1_v: float = typer.Option(30.0, help="L1 speed [m/s]."),
    l1_decel: float = typer.Option(None, help="L1 worst-case deceleration [m/s²]; default a_x_d."),
    f_p: float = typer.Option(-20.0, help="Follower position [m]."),
    f_v: float = typer.Option(30.0, help="Follower speed [m/s]."),
    aggressive: bool = typer.Option(True, "--aggressive/--collaborative", help="Follower's assumed worst case."),
    params_file: Path = typer.Option(None, "--params", help="YAML/JSON file with Params fields."),
) -> None:
    """Verify one state: does a safe evasion trajectory exist? Prints the plan as JSON.

    Example: safelane check --ego-py 1.5 --ego-vy 0.6 --f-p -12 --aggressive
    """
    from ..config import load_params
    from ..safety import Reason, plan_evasion

    params = load_params(params_file)
    decel = params.a_x_d if l1_decel is None else l1_decel
    try:
        plan = plan_evasion(ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, decel, f_p, f_v, aggressive, params)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from exc
    reasons = [r.name for r in Reason if r and int(plan.reason) & int(r)]
    out = {
        "evasion_exists": bool(plan.feasible),
        "reasons": reasons,
        "t_y_f": float(plan.t_y_f),
        "t_y_switch": float(plan.t_y_switch),
        "t_x1": float(plan.t_x1),
        "t_x2": float(plan.t_x2),
        "min_gap_leader_m": float(plan.min_gap_leader),
        "min_gap_follower_m": float(plan.min_gap_follower),
        "params": params.model_dump(),
    }
    typer.echo(json.dumps(out, indent=2))
