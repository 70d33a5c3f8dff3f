"""The paper's Figures 4–6 redrawn from our results, Table 1 as a figure, and our own figures.

Every function takes a tidy frame (a per-cell summary of :func:`safelane.sim.metrics.summarize`, or the trace of
``fig5_example``) and an output folder, writes ``<stem>.png`` and ``<stem>.svg`` and returns their paths. Rates are
drawn with their 95 % Wilson intervals as error bars. Planners keep one colour, marker and line style everywhere.

matplotlib is imported inside the functions and figures are drawn on an explicit Agg canvas (no pyplot, no global
backend switch), so plotting never changes the caller's matplotlib state. SVGs are written with a fixed hash salt
and no date, so the same results give the same files.

Legibility: a figure is drawn at most :data:`MAX_WIDTH_IN` inches wide and no text is set below
:data:`MIN_FONT_PT`, so at the report's page width (``document.CONTENT_WIDTH_PX``) every label is at least
:func:`smallest_text_px` ≥ 12 CSS pixels tall (tests/test_report_figures.py checks each figure).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from ..experiments.paper_data import PLANNERS, TABLE1

#: One style per planner, shared by every figure.
PLANNER_STYLES: dict[str, dict] = {
    "CV_all": {"color": "#1f77b4", "marker": "o", "linestyle": "-"},
    "CV_follow": {"color": "#ff7f0e", "marker": "s", "linestyle": "--"},
    "CV_none": {"color": "#2ca02c", "marker": "^", "linestyle": "-."},
    "No_agg_assess": {"color": "#d62728", "marker": "v", "linestyle": ":"},
}
#: Resolution of the PNGs; the report shows them at their pixel size, scaled down to the page width if wider.
DPI = 150
#: Widest figure [in]: 1500 px at DPI, shown at 1100 px, so 8 pt text is 12 px on the page.
MAX_WIDTH_IN = 10.0
#: Smallest font of any text in a figure [pt].
MIN_FONT_PT = 8.0
_DECEL_LABEL = "sudden deceleration of $L_{N+1}$, $a_{x,N+1,d}$ [m/s²]"
_SECONDARY_STYLES = ("-", "--", ":", "-.")


def import_plotting() -> None:
    """Import what drawing a figure needs (matplotlib's figure, its Agg and SVG backends): a process that is about
    to fork workers that draw imports it once instead of once in each worker."""
    import matplotlib.backends.backend_agg
    import matplotlib.backends.backend_svg
    import matplotlib.figure  # noqa: F401


def _figure(ncols: int = 1, width: float = 5.0, height: float = 3.6):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(min(width * ncols, MAX_WIDTH_IN), height), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, ncols, squeeze=False)[0]
    return fig, list(axes)


def _save(fig, out_dir: Path, stem: str) -> list[Path]:
    import matplotlib

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    png, svg = out_dir / f"{stem}.png", out_dir / f"{stem}.svg"
    # No rc setting may give the figure a layout engine again once its layout is solved.
    keep = {"svg.hashsalt": "safelane", "figure.autolayout": False, "figure.constrained_layout.use": False}
    with matplotlib.rc_context(keep):
        # The layout is solved once, at the PNG's resolution, and kept for both files: savefig would solve it for
        # each file, each time after a draw pass of its own that only measures.
        engine = fig.get_layout_engine()
        if engine is not None:
            fig.set_dpi(DPI)
            engine.execute(fig)
            fig.set_layout_engine(None)
        fig.savefig(png, dpi=DPI, metadata={"Software": None})
        fig.savefig(svg, metadata={"Date": None})
    return [png, svg]


def smallest_text_px(fig, content_width_px: float | None = None) -> tuple[float, str]:
    """``(size, text)`` of the smallest visible text of ``fig`` in CSS pixels as the report shows the PNG: at its
    pixel size (``DPI``), scaled down to ``content_width_px`` when wider."""
    from matplotlib.text import Text

    from .document import CONTENT_WIDTH_PX

    natural = fig.get_figwidth() * DPI
    scale = min(1.0, (content_width_px or CONTENT_WIDTH_PX) / natural)
    sizes = [(float(t.get_fontsize()) * DPI / 72 * scale, t.get_text()) for t in fig.findobj(Text)
             if t.get_visible() and t.get_text().strip()]  # fmt: skip
    return min(sizes) if sizes else (float("inf"), "")


def _planner_order(planners) -> list[str]:
    present = list(dict.fromkeys(planners))
    return sorted(present, key=lambda p: PLANNERS.index(p) if p in PLANNERS else len(PLANNERS))


def _errorbar(ax, rows: pd.DataFrame, x: str, rate: str, offset: float = 0.0, **style) -> None:
    rows = rows.sort_values(x)
    y = rows[f"{rate}_rate"].to_numpy(float)
    err = np.vstack([y - rows[f"{rate}_lo"].to_numpy(float), rows[f"{rate}_hi"].to_numpy(float) - y])
    ax.errorbar(rows[x].to_numpy(float) + offset, y, yerr=np.clip(err, 0, None), capsize=3, markersize=5, **style)


def _by_planner(ax, frame: pd.DataFrame, x: str, rate: str = "success", dodge: float = 0.0) -> None:
    """One line per planner (and one line style per decel value when decel is not on the x axis and varies)."""
    planners = _planner_order(frame["planner"])
    decels = [None] if x == "decel" else sorted(frame["decel"].unique())
    for i, planner in enumerate(planners):
        style = dict(PLANNER_STYLES.get(planner, {}))
        offset = dodge * (i - (len(planners) - 1) / 2)
        for j, decel in enumerate(decels):
            rows = frame[(frame["planner"] == planner) & ((frame["decel"] == decel) if decel is not None else True)]
            label = planner if len(decels) == 1 else f"{planner}, a={decel:g}"
            if len(decels) > 1:
                style["linestyle"] = _SECONDARY_STYLES[j % len(_SECONDARY_STYLES)]
            _errorbar(ax, rows, x, rate, offset, label=label, **style)


def _rate_axis(ax, label: str = "lane-change success rate") -> None:
    ax.set_ylim(-0.03, 1.03)
    ax.set_ylabel(label)
    ax.grid(True, alpha=0.3)


def fig4(summary: pd.DataFrame, out_dir: Path, *, n_leaders: int = 5, stem: str = "fig4_n5") -> list[Path]:
    """Paper Fig. 4: success rate vs ``a_x_N+1_d`` for ``N = n_leaders``, one line per planner."""
    frame = summary[(summary["n_leaders"] == n_leaders) & (summary["p_v"] == 0.0)]
    title = f"Success rate, N = {n_leaders} (cf. paper Fig. 4)"
    return _success_vs(frame, out_dir, "decel", _DECEL_LABEL, title, stem, dodge=0.06)


def table1(summary: pd.DataFrame, out_dir: Path, *, stem: str = "table1") -> list[Path]:
    """Table 1 as a figure: one panel per N; ours with intervals, the paper's published values as crosses."""
    ns = sorted(summary["n_leaders"].unique())
    fig, axes = _figure(len(ns), width=3.4, height=3.6)
    published = {n for n, _ in TABLE1}
    for ax, n in zip(axes, ns, strict=True):
        frame = summary[summary["n_leaders"] == n]
        _by_planner(ax, frame, "decel", dodge=0.06)
        if n in published:
            for planner in _planner_order(frame["planner"]):
                k = PLANNERS.index(planner)
                points = sorted((d, values[k]) for (m, d), values in TABLE1.items() if m == n)
                ax.plot(*zip(*points, strict=True), "x", color=PLANNER_STYLES[planner]["color"], markersize=8)
            ax.set_title(f"N = {n}: ours (lines), paper (×)", fontsize=10)
        else:
            ax.set_title(f"N = {n}: our prediction", fontsize=10)
        _rate_axis(ax)
        ax.set_xlabel("$a_{x,N+1,d}$ [m/s²]")
    for ax in axes[1:]:
        ax.set_ylabel("")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncols=len(labels), fontsize=9, frameon=False)
    return _save(fig, out_dir, stem)


def fig5(trace: pd.DataFrame, out_dir: Path, *, y_boundary: float = 1.75, stem: str = "fig5_example") -> list[Path]:
    """Paper Fig. 5: the ego's lateral position and longitudinal speed over time under every planner."""
    fig, (ax_y, ax_v) = _figure(2)
    for planner in _planner_order(trace["planner"]):
        rows = trace[trace["planner"] == planner].sort_values("t")
        style = {k: v for k, v in PLANNER_STYLES.get(planner, {}).items() if k != "marker"}
        ax_y.plot(rows["t"], rows["ego_y"], label=planner, **style)
        ax_v.plot(rows["t"], rows["ego_vx"], label=planner, **style)
    ax_y.axhline(y_boundary, color="0.4", linewidth=1, linestyle=(0, (5, 5)))
    ax_y.annotate("lane boundary", (0.02, y_boundary), xycoords=("axes fraction", "data"), va="bottom", fontsize=8)
    ax_y.set_ylabel("ego lateral position $y$ [m]")
    ax_v.set_ylabel("ego longitudinal speed $v_x$ [m/s]")
    for ax in (ax_y, ax_v):
        ax.set_xlabel("time $t$ [s]")
        ax.grid(True, alpha=0.3)
    ax_y.legend(fontsize=8)
    fig.suptitle("Example scenario, N = 5, $a_{x,N+1,d}$ = 5 m/s² (cf. paper Fig. 5)")
    return _save(fig, out_dir, stem)


def fig6(summary: pd.DataFrame, out_dir: Path, *, stem: str = "fig6_violation") -> list[Path]:
    """Paper Fig. 6: collision rate and success rate vs ``a_x_N+1_d``, one line per promise-violation rate."""
    from matplotlib import colormaps

    fig, (ax_c, ax_s) = _figure(2)
    p_vs = sorted(summary["p_v"].unique())
    planners = _planner_order(summary["planner"])
    cmap = colormaps["viridis"]
    for i, p_v in enumerate(p_vs):
        colour = cmap(i / max(1, len(p_vs) - 1) * 0.9)
        for j, planner in enumerate(planners):
            rows = summary[(summary["p_v"] == p_v) & (summary["planner"] == planner)]
            label = f"$p_v$ = {p_v:g}" + (f", {planner}" if len(planners) > 1 else "")
            style = {"color": colour, "marker": "o", "linestyle": _SECONDARY_STYLES[j % len(_SECONDARY_STYLES)]}
            offset = 0.04 * (i - (len(p_vs) - 1) / 2)
            _errorbar(ax_c, rows, "decel", "collision", offset, label=label, **style)
            _errorbar(ax_s, rows, "decel", "success", offset, label=label, **style)
    _rate_axis(ax_c, "collision rate")
    _rate_axis(ax_s)
    for ax in (ax_c, ax_s):
        ax.set_xlabel(_DECEL_LABEL)
    ax_s.legend(fontsize=8)
    n = ", ".join(str(v) for v in sorted(summary["n_leaders"].unique()))
    fig.suptitle(f"Unexpected promise violation, N = {n} (cf. paper Fig. 6)")
    return _save(fig, out_dir, stem)


def penetration(summary: pd.DataFrame, out_dir: Path, *, stem: str = "penetration") -> list[Path]:
    """Ours: success rate vs the share of connected vehicles (random placement), one line per planner."""
    title = f"Ours: success vs penetration, $a_{{x,N+1,d}}$ = {_decels(summary)}"
    xlabel = "share of connected vehicles (penetration)"
    return _success_vs(summary, out_dir, "penetration", xlabel, title, stem, dodge=0.008)


def leaders(summary: pd.DataFrame, out_dir: Path, *, stem: str = "leaders") -> list[Path]:
    """Ours: success rate vs the number of connected leaders N, one line per planner."""
    title = f"Ours: success vs N, $a_{{x,N+1,d}}$ = {_decels(summary)}"
    return _success_vs(summary, out_dir, "n_leaders", "number of connected leaders N", title, stem, dodge=0.08)


def _decels(summary: pd.DataFrame) -> str:
    return ", ".join(f"{d:g}" for d in sorted(summary["decel"].unique()))


def _success_vs(frame, out_dir: Path, x: str, xlabel: str, title: str, stem: str, dodge: float) -> list[Path]:
    """One panel: success rate against ``x``, one line per planner (see :func:`_by_planner`)."""
    fig, (ax,) = _figure()
    _by_planner(ax, frame, x, dodge=dodge)
    _rate_axis(ax)
    ax.set_xlabel(xlabel)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)
    return _save(fig, out_dir, stem)


#: Experiment name -> ``(data, out_dir, y_boundary) -> paths``; ``data`` is the summary, or the trace for fig5.
FIGURES: dict[str, Callable[[pd.DataFrame, Path, float], list[Path]]] = {
    "fig4_n5": lambda data, out, y_boundary: fig4(data, out),
    "table1": lambda data, out, y_boundary: table1(data, out),
    "fig5_example": lambda data, out, y_boundary: fig5(data, out, y_boundary=y_boundary),
    "fig6_violation": lambda data, out, y_boundary: fig6(data, out),
    "penetration": lambda data, out, y_boundary: penetration(data, out),
    "leaders": lambda data, out, y_boundary: leaders(data, out),
    "rss_baseline": lambda data, out, y_boundary: _rss_figure(data, out),
    "table1_safe_mode": lambda data, out, y_boundary: table1(data, out, stem="table1_safe_mode"),
    "table1_rules": lambda data, out, y_boundary: table1(data, out, stem="table1_rules"),
}


def _rss_figure(summary: pd.DataFrame, out_dir: Path) -> list[Path]:
    from .rss import figure  # it draws with this module's helpers

    return figure(summary, out_dir)
