"""The ``rss_baseline`` experiment in the report: its figure, its table and the paragraph stating from the numbers what
connectivity buys over RSS and where RSS's responsibility assumption leads to collisions (docs/rss.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..experiments.rss_baseline import overview
from .document import Document
from .figures import _figure, _save

_RATES = (("success", "#2ca02c", "success"), ("collision", "#d62728", "collision"),
          ("safety_violation", "#ff7f0e", "$p_m$ violation"))  # fmt: skip


def figure(summary: pd.DataFrame, out_dir: Path, *, stem: str = "rss_baseline") -> list[Path]:
    """One panel per follower behaviour: success, collision and ``p_m``-violation rates per planner, pooled over the
    grid, with 95 % Wilson intervals."""
    view = overview(summary)
    followers = list(dict.fromkeys(view["follower"]))
    fig, axes = _figure(len(followers), width=5.2, height=3.8)
    for ax, follower in zip(axes, followers, strict=True):
        rows = view[view["follower"] == follower]
        x = np.arange(len(rows))
        for k, (rate, color, label) in enumerate(_RATES):
            y = rows[f"{rate}_rate"].to_numpy(float)
            err = np.vstack([y - rows[f"{rate}_lo"].to_numpy(float), rows[f"{rate}_hi"].to_numpy(float) - y])
            ax.bar(x + (k - 1) * 0.27, y, 0.27, yerr=np.clip(err, 0, None), color=color, label=label, capsize=2)
        ax.set_xticks(x, rows["planner"], rotation=45, ha="right", fontsize=8)
        ax.set_ylim(0, 1.05)
        ax.set_title(f"F {follower.replace('_', ' ')}", fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].set_ylabel("rate (pooled over N and $a_{x,N+1,d}$)")
    axes[0].legend(fontsize=8, loc="upper center")
    return _save(fig, out_dir, stem)


def section(doc: Document, summary: pd.DataFrame) -> None:
    """The table (pooled over the grid) and the paragraph with the measured numbers."""
    view = overview(summary)
    header = ["F", "planner", "samples", "success [95 % CI]", "collision [95 % CI]", "p_m violation [95 % CI]",
              "hit by F", "ego hit L1"]  # fmt: skip
    rows = []
    for r in view.itertuples():
        cells = [f"{getattr(r, f'{c}_rate'):.3f} [{getattr(r, f'{c}_lo'):.3f}, {getattr(r, f'{c}_hi'):.3f}]"
                 for c in ("success", "collision", "safety_violation")]  # fmt: skip
        rows.append([r.follower, r.planner, r.samples, *cells, f"{r.collision_with_follower_rate:.3f}",
                     f"{r.collision_with_leader_rate:.3f}"])  # fmt: skip
    doc.table(header, rows)
    doc.paragraph(paragraph(view))


def paragraph(view: pd.DataFrame) -> str:
    """What the numbers say, quoting them (``view``: :func:`safelane.experiments.rss_baseline.overview`)."""
    from ..baselines.rss import RssParams, longitudinal_safe_distance

    planners, followers = set(view["planner"]), list(dict.fromkeys(view["follower"]))

    def r(follower, planner, col="success"):
        row = view[(view["follower"] == follower) & (view["planner"] == planner)]
        return float(row[f"{col}_rate"].iloc[0]) if len(row) else float("nan")

    rss = [p for p in ("RSS", "RSS_V2X", "RSS_matched", "RSS_V2X_matched") if p in planners]
    if not rss or "CV_all" not in planners:
        return "The RSS comparison needs CV_all and at least one RSS variant in the grid."
    d = RssParams()
    ahead = longitudinal_safe_distance(30.0, 30.0, d.response_time_ego, d.accel_max, d.brake_min, d.brake_max)
    behind = longitudinal_safe_distance(30.0, 30.0, d.response_time_other, d.accel_max, d.brake_min, d.brake_max)
    base = "collaborative" if "collaborative" in followers else followers[0]
    parts = []
    for f in followers:
        best = max(rss, key=lambda p: r(f, p))
        collide = ", ".join(f"{r(f, p, 'collision'):.1%} ({p})" for p in rss)
        hit_by_f = max(rss, key=lambda p: r(f, p, "collision_with_follower"))
        text = (
            f"**F {f.replace('_', ' ')}**: CV_all completes {r(f, 'CV_all'):.1%} of the lane changes with "
            f"{r(f, 'CV_all', 'collision'):.1%} collisions; the best RSS variant, {best}, {r(f, best):.1%} "
            f"(RSS collisions: {collide}; p_m violations up to "
            f"{max(r(f, p, 'safety_violation') for p in rss):.1%})."
        )
        if r(f, hit_by_f, "collision_with_follower") > 0:
            text += (
                f" F rear-ends the ego in {r(f, hit_by_f, 'collision_with_follower'):.1%} of {hit_by_f}'s lane "
                "changes: RSS let the ego in at its safe distance and calls these F's fault; here they count as "
                "collisions."
            )
        if f == "ignores_ego" and r(f, "CV_all", "collision") > 0:
            text += (
                " The paper's shield trusts F's declared collaboration (outside its assumptions here), so CV_all "
                "collides more than RSS, which never trusts F."
            )
        parts.append(text)
    parts.append(
        f"RSS with ad-rss's default parameters completes {max(r(f, 'RSS') for f in followers):.1%} at best: at "
        f"30 m/s it asks {ahead:.0f} m behind L1 and {behind:.0f} m ahead of F (response times 1 s and 2 s, "
        "brake_min 4 m/s²), against gaps of 17–22 m. With this world's limits (RSS_matched) it changes lanes, but "
        "its lateral safe distance lets the ego straddle the lane line next to a vehicle, which the paper counts as a "
        f"p_m violation (RSS's safe distances are not the paper's p_m, so success rates compare different "
        f"margins). What connectivity buys: with F {base.replace('_', ' ')}, CV_all completes "
        f"{100 * (r(base, 'CV_all') - max(r(base, p) for p in rss)):+.1f} percentage points more than the best RSS "
        f"variant, without a p_m violation; within RSS, V2X (L1's promised bound as its brake_max) adds "
        f"{100 * (r(base, 'RSS_V2X_matched') - r(base, 'RSS_matched')):+.1f} points (RSS_V2X_matched vs "
        "RSS_matched)."
    )
    return " ".join(parts)
