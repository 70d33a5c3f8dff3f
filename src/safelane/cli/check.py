"""``safelane check``: one state → verdict and evasion plan as JSON."""

from __future__ import annotations

import json
import re
from pathlib import Path

import typer

from . import app


@app.command()
def check(
    ego_px: float = typer.Option(0.0, help="Ego longitudinal position [m]."),
    ego_py: float = typer.Option(
        1.2,
        help="Ego lateral centre position [m]: original lane centre 0, target lane centre lane_width (3.5 "
        "by default); within [-lane_width/2, 1.5*lane_width].",
    ),
    ego_vx: float = typer.Option(30.0, help="Ego speed [m/s]."),
    ego_vy: float = typer.Option(0.5, help="Ego lateral speed [m/s], positive toward the target lane."),
    l1_p: float = typer.Option(20.0, help="L1 position [m]."),
    l1_v: float = typer.Option(30.0, help="L1 speed [m/s]."),
    l1_decel: float = typer.Option(None, help="L1 worst-case deceleration [m/s²]; default a_x_d, or from --chain-p."),
    chain_p: list[float] = typer.Option(
        None, "--chain-p", help="Positions of L2..L(N+1) [m] (repeat): L1's worst case then follows the chain."
    ),
    chain_v: list[float] = typer.Option(None, "--chain-v", help="Speeds of L2..L(N+1) [m/s] (repeat, as --chain-p)."),
    promise: float = typer.Option(0.5, "--promise", help="Promised max deceleration of L1..LN [m/s²] (--chain-p)."),
    f_p: float = typer.Option(-20.0, help="Follower position [m]."),
    f_v: float = typer.Option(30.0, help="Follower speed [m/s]."),
    aggressive: bool = typer.Option(True, "--aggressive/--collaborative", help="Follower's assumed worst case."),
    params_file: Path = typer.Option(None, "--params", help="YAML/JSON file with Params fields."),
    preset: str = typer.Option(
        None, "--preset", help="Take Params from a preset (name such as 'paper' or a YAML path); default Params()."
    ),
) -> None:
    """Verify one state: does a safe evasion trajectory exist? Prints the plan as JSON.

    Parameters: --preset paper (the calibrated ones), --params FILE, or the uncalibrated defaults. With
    --chain-p/--chain-v (L2..L(N+1)), L1's worst-case deceleration comes from the connected chain (Eqs. 1–3).

    Example: safelane check --ego-py 1.5 --ego-vy 0.6 --f-p -12 --aggressive
    Example: safelane check --preset paper --chain-p 40 --chain-p 60 --chain-v 30 --chain-v 30
    """
    from ..config import load_params
    from ..safety import Reason, plan_evasion, worst_case_leader_decel
    from ..sim.preset import load_preset

    if preset is not None and params_file is not None:
        raise typer.BadParameter("give either --preset or --params, not both", param_hint="--preset")
    try:
        params = load_preset(preset).params if preset is not None else load_params(params_file)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--preset" if preset is not None else "--params") from exc
    chain_p, chain_v = list(chain_p or []), list(chain_v or [])
    if len(chain_p) != len(chain_v):
        raise typer.BadParameter(
            f"give one --chain-v per --chain-p; got {len(chain_p)} positions and {len(chain_v)} speeds",
            param_hint="--chain-v",
        )
    if chain_p and l1_decel is not None:
        raise typer.BadParameter("give either --l1-decel or a chain (--chain-p), not both", param_hint="--l1-decel")
    _check_geometry(params, ego_py, l1_p, f_p, chain_p)
    try:
        if chain_p:
            n = len(chain_p)
            decel = float(worst_case_leader_decel([l1_p, *chain_p], [l1_v, *chain_v], [promise] * n, params))
        else:
            decel = params.a_x_d if l1_decel is None else l1_decel
        plan = plan_evasion(ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, decel, f_p, f_v, aggressive, params)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint=_option_named_in(str(exc))) from exc
    reasons = [r.name for r in Reason if r and int(plan.reason) & int(r)]
    out = {
        "evasion_exists": bool(plan.feasible),
        "reasons": reasons,
        "l1_decel": float(decel),
        "t_y_f": float(plan.t_y_f),
        "t_y_switch": float(plan.t_y_switch),
        "t_x1": float(plan.t_x1),
        "t_x2": float(plan.t_x2),
        "min_gap_leader_m": float(plan.min_gap_leader),
        "min_gap_follower_m": float(plan.min_gap_follower),
        "preset": preset,
        "params": params.model_dump(),
    }
    typer.echo(json.dumps(out, indent=2))


def _check_geometry(params, ego_py: float, l1_p: float, f_p: float, chain_p: list[float]) -> None:
    """Refuse a state outside the analysis' world, naming the option: the ego's centre outside the original and the
    target lane, F ahead of L1, or a leader behind the one before it (one lane: no vehicle passes through another).
    L1 behind the ego or F ahead of it are answered (no evasion: the gap is below ``p_m`` from the start)."""
    lo, hi = -0.5 * params.lane_width, 1.5 * params.lane_width
    if not lo <= ego_py <= hi:
        raise typer.BadParameter(
            f"{ego_py:g} m is outside the two lanes: the ego's lateral centre position must lie in [{lo:g}, {hi:g}] m "
            f"(original lane centre 0, target lane centre lane_width={params.lane_width:g}, outer edges at "
            "-lane_width/2 and 1.5*lane_width)",
            param_hint="--ego-py",
        )
    if f_p > l1_p:
        raise typer.BadParameter(
            f"the follower at {f_p:g} m is ahead of L1 at {l1_p:g} m; F and L1 share the target lane, F behind L1",
            param_hint="--f-p",
        )
    positions = [l1_p, *chain_p]
    for i in range(1, len(positions)):
        if positions[i] < positions[i - 1]:
            raise typer.BadParameter(
                f"L{i + 1} at {positions[i]:g} m is behind L{i} at {positions[i - 1]:g} m; give L2..L(N+1) nearest "
                "first, each at or ahead of the one before it",
                param_hint="--chain-p",
            )


_STATE_OPTIONS = ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "f_p", "f_v")


#: The chain API's argument names and the options that give them (``worst_case_leader_decel(p, v, promise_decel)``).
_CHAIN_OPTIONS = {"promise_decel": "--promise", "p": "--chain-p", "v": "--chain-v"}


def _option_named_in(message: str) -> str | None:
    """The option whose argument the safety API's message names (``ego_vx`` → ``--ego-vx``, ``promise_decel`` →
    ``--promise``), if any."""
    for name in _STATE_OPTIONS:
        if re.search(rf"\b{name}\b", message):
            return "--" + name.replace("_", "-")
    for name, option in _CHAIN_OPTIONS.items():
        if re.match(rf"{name}\b", message):  # the chain's messages start with the argument's name
            return option
    return None
