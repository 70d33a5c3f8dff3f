"""The report of ``safelane replay``: the summary table, a figure per lane change, the distributions.

Everything here reads the tables of :func:`safelane.recorded.replay.replay` (``events``, ``rows``); nothing is
recomputed. The table's rows (:func:`summary_rows`) are the ones docs/real_traffic.md quotes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .document import Document
from .figures import _figure, _save

#: Colours of the verdict bands.
VERDICT_COLOURS = {"proceed": "#4caf50", "hesitate": "#ffb300", "abort": "#e53935", "crossed": "#bdbdbd",
                   "completed": "#bdbdbd"}  # fmt: skip
SUMMARY_HEADER = ["connected", "rule", "events", "allowed at the human's crossing",
                  "delay until allowed: median / worst [s]", "never allowed in the window",
                  "smallest margin to L1 / F [m]"]  # fmt: skip


def _fmt(x: float, fmt: str = ".1f") -> str:
    return "—" if not np.isfinite(x) else format(x, fmt)


def summary_rows(events: pd.DataFrame) -> list[list[str]]:
    """One row per connectivity share and rule (the shield, RSS): events, share allowed at the human's crossing,
    the delay until the crossing check first allows it (median, worst; events never allowed in the window are
    counted apart), the smallest margins at the crossing step."""
    out = []
    for share, group in events.groupby("connected_share", sort=True):
        for tag, name in (("shield", "shield"), ("rss", "RSS")):
            n = len(group)
            allowed = int(group[f"{tag}_allowed"].sum())
            delay = group[f"{tag}_delay_s"].to_numpy(float)
            never = int(np.isnan(delay).sum())
            finite = delay[np.isfinite(delay)]
            median = float(np.median(finite)) if len(finite) else np.nan
            worst = float(finite.max()) if len(finite) else np.nan
            pre = "" if tag == "shield" else "rss_"
            l1 = group[f"{pre}margin_l1_m"].to_numpy(float)
            f = group[f"{pre}margin_f_m"].to_numpy(float)
            l1_min = np.nanmin(np.where(np.isfinite(l1), l1, np.nan)) if np.isfinite(l1).any() else np.nan
            f_min = np.nanmin(np.where(np.isfinite(f), f, np.nan)) if np.isfinite(f).any() else np.nan
            out.append([f"{share:g}", name, str(n), f"{allowed} of {n}", f"{_fmt(median)} / {_fmt(worst)}", str(never),
                        f"{_fmt(l1_min)} / {_fmt(f_min)}"])  # fmt: skip
    return out


def event_figure(rows: pd.DataFrame, event: pd.Series, out_dir: Path, stem: str) -> list[Path]:
    """The human's lateral position relative to the line crossed, with four verdict bands above it: the shield on the
    human's step, the shield's crossing check, RSS on the step, RSS's crossing check."""
    from matplotlib.patches import Patch

    fig, (ax,) = _figure(1, width=7.0, height=3.4)
    t = rows["t_rel_s"].to_numpy()
    ax.plot(t, rows["y_to_line_m"], color="#222", lw=1.6, label="human (lateral, toward the target lane)")
    ax.axhline(0.0, color="#555", ls="--", lw=0.8)
    ax.axvline(0.0, color="#555", ls=":", lw=0.8)
    low, high = float(np.nanmin(rows["y_to_line_m"])), float(np.nanmax(rows["y_to_line_m"]))
    span = max(high - low, 1.0)
    bands = (("shield_verdict", "shield: step"), ("shield_crossing_verdict", "shield: cross now"),
             ("rss_verdict", "RSS: step"), ("rss_crossing_verdict", "RSS: cross now"))  # fmt: skip
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.1
    for k, (col, label) in enumerate(bands):
        base = high + span * (0.12 + 0.14 * k)
        colours = [VERDICT_COLOURS.get(v, "#999") for v in rows[col]]
        ax.bar(t, span * 0.11, width=dt, bottom=base, color=colours, align="edge", linewidth=0)
        ax.text(t.min() + 0.03, base + span * 0.055, label, ha="left", va="center", fontsize=8,
                bbox={"facecolor": "white", "alpha": 0.75, "linewidth": 0, "pad": 1.0})  # fmt: skip
    ax.set_ylim(low - 0.1 * span, high + span * 0.75)
    ax.set_xlabel("time from the crossing [s]")
    ax.set_ylabel("lateral to the line [m]")
    handles = [Patch(color=c, label=v) for v, c in VERDICT_COLOURS.items() if v != "completed"]
    ax.legend(handles=handles, loc="lower right", fontsize=8, ncols=4)
    ax.set_title(f"vehicle {event['vehicle_id']}: lane {event['from_lane']} → {event['to_lane']} "
                 f"({Path(str(event['file'])).name}, connected {event['connected_share']:g})", fontsize=9)  # fmt: skip
    return _save(fig, out_dir, stem)


def distributions_figure(events: pd.DataFrame, out_dir: Path, stem: str = "distributions") -> list[Path]:
    """Delay until allowed and the margins at the crossing, shield beside RSS, over every event and share."""
    fig, axes = _figure(3, width=3.4, height=3.0)
    for tag, colour, name in (("shield", "#1e88e5", "shield"), ("rss", "#8e24aa", "RSS")):
        pre = "" if tag == "shield" else "rss_"
        delay = events[f"{tag}_delay_s"].to_numpy(float)
        axes[0].hist(delay[np.isfinite(delay)], bins=20, alpha=0.6, color=colour, label=name)
        for ax, col in ((axes[1], f"{pre}margin_l1_m"), (axes[2], f"{pre}margin_f_m")):
            values = events[col].to_numpy(float)
            ax.hist(values[np.isfinite(values)], bins=20, alpha=0.6, color=colour, label=name)
    for ax, label in zip(axes, ("delay until allowed [s]", "margin to L1 at crossing [m]",
                                "margin to F at crossing [m]"), strict=True):  # fmt: skip
        ax.set_xlabel(label)
        ax.set_ylabel("events")
        ax.legend(fontsize=8)
    return _save(fig, out_dir, stem)


def write_report(run_dir: Path, events: pd.DataFrame, rows: pd.DataFrame, skipped: list[tuple[str, str]],
                 settings: dict, adrss: tuple[int, int] | None) -> tuple[Path, Path]:  # fmt: skip
    """``report.md`` and ``report.html`` in ``run_dir`` (figures under ``figures/``)."""
    run_dir = Path(run_dir)
    figures = run_dir / "figures"
    doc = Document("Recorded lane changes: the shield's open-loop verdicts")
    doc.contents()
    doc.heading(1, "What was replayed")
    doc.paragraph(
        f"Preset `{settings['preset']}`, variant `{settings['variant']}` beside RSS (`RSS`; `RSS_V2X` where some "
        "vehicles are connected), judged open loop: the human keeps driving as recorded, and every 0.1 s a fresh "
        "shield judges the human's next step (proceed / hesitate / abort) and whether crossing *now* would be allowed "
        "(the crossing check). Connectivity is an assumption: each vehicle connected with probability "
        f"{', '.join(str(s) for s in settings['connected_shares'])} (seed {settings['seed']}). "
        "Assumptions and definitions: docs/real_traffic.md."
    )  # fmt: skip
    doc.heading(1, "Summary")
    doc.table(SUMMARY_HEADER, summary_rows(events) if len(events) else [])
    if adrss is not None:
        doc.paragraph(f"ad-rss's own pair checks on the crossing steps agree with the NumPy RSS in {adrss[0]} of "
                      f"{adrss[1]} pairs.")  # fmt: skip
    if skipped:
        doc.heading(1, "Skipped")
        doc.table(["what", "why"], [[w, why] for w, why in skipped])
    if len(events):
        doc.heading(1, "Distributions")
        paths = distributions_figure(events, figures)
        doc.image(paths[0], f"figures/{paths[0].name}", "Delay until the crossing check allows the crossing, and "
                  "the margins at the human's crossing step, over every event and connectivity share.")  # fmt: skip
        doc.heading(1, "Every lane change")
        for i, (_, event) in enumerate(events.iterrows()):
            mask = ((rows["file"] == event["file"]) & (rows["event"] == event["event"])
                    & (rows["connected_share"] == event["connected_share"]))  # fmt: skip
            stem = f"event_{i:03d}"
            paths = event_figure(rows[mask], event, figures, stem)
            verdict = "allowed" if event["shield_allowed"] else f"not allowed ({event['shield_verdict_at_crossing']})"
            doc.heading(2, f"Vehicle {event['vehicle_id']}, {Path(str(event['file'])).name}, connected "
                           f"{event['connected_share']:g}")  # fmt: skip
            doc.paragraph(f"Lane {event['from_lane']} → {event['to_lane']} at t = {event['crossing_t_s']:.1f} s; the "
                          f"shield: {verdict} at the human's crossing, delay {_fmt(event['shield_delay_s'])} s; RSS: "
                          f"{'allowed' if event['rss_allowed'] else 'not allowed'}, delay "
                          f"{_fmt(event['rss_delay_s'])} s.")  # fmt: skip
            doc.image(paths[0], f"figures/{paths[0].name}", "Lateral position relative to the line crossed; bands: "
                      "the verdicts every 0.1 s.")  # fmt: skip
    md, page = run_dir / "report.md", run_dir / "report.html"
    md.write_text(doc.to_markdown(), encoding="utf-8")
    page.write_text(doc.to_html(), encoding="utf-8")
    return md, page
