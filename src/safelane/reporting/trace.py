"""Plots of simulation traces (the paper's Figure 5 kind): the ego's lateral position and longitudinal speed.

Only :mod:`safelane.reporting` and the CLI import this module. matplotlib is imported inside the functions and
figures are drawn on an explicit Agg canvas (no pyplot, no global backend switch), so plotting never changes the
caller's matplotlib state and works without a display.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..shield import ABORT, HESITATE

#: Columns a trace must have (``SimResult.trace``).
TRACE_COLUMNS = ("scenario_id", "planner", "t", "ego_y", "ego_vx", "behaviour")

_BEHAVIOUR_MARKS = {HESITATE: ("hesitate", "o", "#ff7f0e"), ABORT: ("abort", "x", "#d62728")}


def plot_trace(
    trace: pd.DataFrame,
    path: Path | str,
    *,
    y_boundary: float | None = 1.75,
    lane_width: float | None = 3.5,
    title: str | None = None,
    others: bool = True,
) -> Path:
    """Draw lateral position and longitudinal speed over time for every (planner, scenario) in ``trace``.

    Args:
        trace: rows of ``SimResult.trace`` (one row per scenario and step; columns :data:`TRACE_COLUMNS`, and
            ``l1_v`` / ``f_v`` for ``others``).
        path: the image file to write (the suffix picks the format, e.g. ``.png`` or ``.svg``); parent folders
            are created.
        y_boundary, lane_width: draw the lane boundary and the target lane's centre (``None`` to omit).
        title: figure title.
        others: with a single scenario, also draw the speeds of L1 and F.

    Steps where the supervisor hesitated or aborted are marked on both panels. Returns ``path``.
    """
    missing = [c for c in TRACE_COLUMNS if c not in trace.columns]
    if missing:
        raise ValueError(f"trace is missing columns {missing}; pass SimResult.trace")
    if trace.empty:
        raise ValueError("trace is empty")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 3.8), layout="constrained")
    FigureCanvasAgg(fig)
    ax_y, ax_v = fig.subplots(1, 2)
    groups = list(trace.groupby(["planner", "scenario_id"], sort=False))
    marked = set()
    for (planner, sid), rows in groups:
        rows = rows.sort_values("t")
        label = planner if trace["scenario_id"].nunique() == 1 else f"{planner} #{sid}"
        (line,) = ax_y.plot(rows["t"], rows["ego_y"], label=label)
        ax_v.plot(rows["t"], rows["ego_vx"], color=line.get_color(), label=f"ego ({label})")
        for code, (name, marker, color) in _BEHAVIOUR_MARKS.items():
            sel = rows[rows["behaviour"] == code]
            if len(sel):
                kw = dict(marker=marker, color=color, linestyle="none", markersize=4)
                ax_y.plot(sel["t"], sel["ego_y"], label=None if name in marked else name, **kw)
                ax_v.plot(sel["t"], sel["ego_vx"], **kw)
                marked.add(name)
    if others and len(groups) == 1:
        rows = groups[0][1].sort_values("t")
        for col, name, style in (("l1_v", "L1", "--"), ("f_v", "F", ":")):
            if col in rows:
                ax_v.plot(rows["t"], rows[col], color="0.35", linestyle=style, label=name)
    if y_boundary is not None:
        ax_y.axhline(y_boundary, color="0.4", linewidth=1, linestyle=(0, (5, 5)), label="lane boundary")
    if lane_width is not None:
        ax_y.axhline(lane_width, color="0.7", linewidth=1, label="target-lane centre")
    ax_y.set_ylabel("ego lateral position $y$ [m]")
    ax_v.set_ylabel("longitudinal speed $v_x$ [m/s]")
    for ax in (ax_y, ax_v):
        ax.set_xlabel("time $t$ [s]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150, metadata={"Software": None} if path.suffix == ".png" else None)
    return path
