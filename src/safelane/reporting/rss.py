"""The ``rss_baseline`` experiment in the report: its figure, its table and the paragraph stating from the numbers what
connectivity buys over RSS and where RSS's responsibility assumption leads to collisions (docs/rss.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..experiments.rss_baseline import overview
from . import prose
from .document import Document
from .figures import _figure, _save

_RATES = (("success", "#2ca02c", "success"), ("collision", "#d62728", "collision"),
          ("safety_violation", "#ff7f0e", "$p_m$ violation"))  # fmt: skip


def figure(summary: pd.DataFrame, out_dir: Path, *, stem: str = "rss_baseline") -> list[Path]:
    """One panel per follower behaviour: success, collision and ``p_m``-violation rates per planner (horizontal bars,
    the planners named once on the left), pooled over the grid, with 95 % Wilson intervals."""
    view = overview(summary)
    followers = list(dict.fromkeys(view["follower"]))
    planners = list(dict.fromkeys(view["planner"]))
    fig, axes = _figure(len(followers), width=3.4, height=1.2 + 0.42 * len(planners))
    y = np.arange(len(planners))[::-1]  # the first planner on top
    for ax, follower in zip(axes, followers, strict=True):
        rows = view[view["follower"] == follower].set_index("planner").loc[planners]
        for k, (rate, color, label) in enumerate(_RATES):
            x = rows[f"{rate}_rate"].to_numpy(float)
            err = np.vstack([x - rows[f"{rate}_lo"].to_numpy(float), rows[f"{rate}_hi"].to_numpy(float) - x])
            ax.barh(y - (k - 1) * 0.27, x, 0.27, xerr=np.clip(err, 0, None), color=color, label=label, capsize=2)
        ax.set_yticks(y, planners if ax is axes[0] else [""] * len(planners), fontsize=9)
        ax.set_xlim(0, 1.05)
        ax.set_xlabel("rate, pooled over N and $a_{x,N+1,d}$", fontsize=9)
        ax.set_title(f"F {follower.replace('_', ' ')}", fontsize=10)
        ax.grid(True, axis="x", alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncols=len(labels), fontsize=9, frameon=False)
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
    """What the numbers say, quoting them (``view``: :func:`safelane.experiments.rss_baseline.overview`).

    Every comparison word, sign and "with"/"without" is chosen by the numbers of ``view`` (see
    :mod:`safelane.reporting.prose`); a difference inside the 95 % intervals is called one.
    """
    from ..baselines.rss import RssParams, longitudinal_safe_distance
    from ..sim.scenario import ScenarioConfig

    planners, followers = set(view["planner"]), list(dict.fromkeys(view["follower"]))
    rows = view.set_index(["follower", "planner"])

    def r(follower, planner, col="success"):
        key = (follower, planner)
        return float(rows.loc[key, f"{col}_rate"]) if key in rows.index else float("nan")

    def ci(follower, planner, col="success"):
        return float(rows.loc[(follower, planner), f"{col}_lo"]), float(rows.loc[(follower, planner), f"{col}_hi"])

    def n(follower, planner):
        return int(rows.loc[(follower, planner), "samples"])

    rss = [p for p in ("RSS", "RSS_V2X", "RSS_matched", "RSS_V2X_matched") if p in planners]
    if not rss or "CV_all" not in planners:
        return "The RSS comparison needs CV_all and at least one RSS variant in the grid."
    parts = []
    for f in followers:
        best = max(rss, key=lambda p: r(f, p))
        diff = r(f, "CV_all") - r(f, best)
        word = prose.more_or_fewer(diff, prose.clearly(ci(f, "CV_all"), ci(f, best)))
        text = (
            f"**F {f.replace('_', ' ')}** ({n(f, 'CV_all')} lane changes per planner): CV_all completes "
            f"{prose.share(r(f, 'CV_all'))} of the lane changes "
            f"{prose.with_or_without(r(f, 'CV_all', 'collision'), n(f, 'CV_all'), 'collision')}; the best RSS "
            f"variant, {best}, completes {prose.share(r(f, best))}, "
        )
        text += (
            "as many within sampling noise" if word == "as many"
            else f"{prose.points(diff, 'fewer' if word == 'more' else 'more')} than CV_all"
        )  # fmt: skip
        colliding = [p for p in rss if prose.count(r(f, p, "collision") * n(f, p)) > 0]
        text += (
            ". No RSS variant collides" if not colliding else ". RSS collisions: " + prose.join(
                [f"{prose.share(r(f, p, 'collision'), n(f, p))} ({p})" for p in colliding])
        )  # fmt: skip
        worst = max(rss, key=lambda p: r(f, p, "safety_violation"))
        text += (
            f"; p_m violations: CV_all {prose.share(r(f, 'CV_all', 'safety_violation'), n(f, 'CV_all'))}, "
            f"RSS up to {prose.share(r(f, worst, 'safety_violation'), n(f, worst))} ({worst})."
        )
        hit_by_f = max(rss, key=lambda p: r(f, p, "collision_with_follower"))
        if r(f, hit_by_f, "collision_with_follower") > 0:
            text += (
                f" F rear-ends the ego in {prose.share(r(f, hit_by_f, 'collision_with_follower'), n(f, hit_by_f))} "
                f"of {hit_by_f}'s lane changes: RSS let the ego in at its safe distance and calls these F's fault; "
                "here they count as collisions."
            )
        most = max(rss, key=lambda p: r(f, p, "collision"))
        order = prose.clearly(ci(f, "CV_all", "collision"), ci(f, most, "collision"))
        if order > 0:
            text += (
                f" CV_all collides more often than any RSS variant ({prose.share(r(f, 'CV_all', 'collision'))} "
                f"against at most {prose.share(r(f, most, 'collision'))})"
                + (": the paper's shield trusts F's declared collaboration (outside its assumptions here), RSS "
                   "never trusts F." if f == "ignores_ego" else ".")
            )  # fmt: skip
        elif order < 0:
            text += " CV_all collides less often than every RSS variant."
        parts.append(text)
    parts.append(_rss_limits(r, followers, rss, longitudinal_safe_distance, RssParams(), ScenarioConfig().gap))
    parts.append(_what_connectivity_buys(r, ci, n, followers, rss))
    return " ".join(p for p in parts if p)


def _rss_limits(r, followers, rss, safe_distance, d, gap) -> str:
    """Why RSS with ad-rss's defaults completes what it does, and what RSS_matched's lateral rule costs."""
    text = ""
    if "RSS" in rss:
        ahead = safe_distance(30.0, 30.0, d.response_time_ego, d.accel_max, d.brake_min, d.brake_max)
        behind = safe_distance(30.0, 30.0, d.response_time_other, d.accel_max, d.brake_min, d.brake_max)
        text = (
            f"RSS with ad-rss's default parameters completes at most {prose.share(max(r(f, 'RSS') for f in followers))}"
            f" of the lane changes: at 30 m/s it asks {ahead:.0f} m behind L1 and {behind:.0f} m ahead of F "
            f"(response times {d.response_time_ego:g} s and {d.response_time_other:g} s, brake_min "
            f"{d.brake_min:g} m/s²), against initial gaps of {gap[0]:g}–{gap[1]:g} m."
        )
    if "RSS_matched" in rss:
        violations = max(r(f, "RSS_matched", "safety_violation") for f in followers)
        text += (
            f" With this world's limits (RSS_matched) it completes up to "
            f"{prose.share(max(r(f, 'RSS_matched') for f in followers))}"
        )
        text += (
            f", with p_m violations in up to {prose.share(violations)} of its lane changes: its lateral safe distance "
            "lets the ego straddle the lane line next to a vehicle, which the paper counts as a p_m violation (RSS's "
            "safe distances are not the paper's p_m, so success rates compare different margins)."
            if violations > 0 else ", without a p_m violation."
        )  # fmt: skip
    return text.strip()


def _what_connectivity_buys(r, ci, n, followers, rss) -> str:
    base = "collaborative" if "collaborative" in followers else followers[0]
    best = max(rss, key=lambda p: r(base, p))
    diff = r(base, "CV_all") - r(base, best)
    word = prose.more_or_fewer(diff, prose.clearly(ci(base, "CV_all"), ci(base, best)))
    amount = "as many lane changes (within sampling noise) as" if word == "as many" else (
        prose.points(diff, word) + " lane changes than")  # fmt: skip
    v_cv, v_best = r(base, "CV_all", "safety_violation"), r(base, best, "safety_violation")
    v_word = prose.more_or_fewer(v_cv - v_best, prose.clearly(ci(base, "CV_all", "safety_violation"),
                                                              ci(base, best, "safety_violation")))  # fmt: skip
    text = (
        f"With F {base.replace('_', ' ')}, CV_all completes {amount} the best RSS variant ({best}: "
        f"{prose.share(r(base, 'CV_all'))} vs {prose.share(r(base, best))}), "
        + (f"{prose.with_or_without(v_cv, n(base, 'CV_all'), 'p_m violation')}"
           if v_cv == 0 else f"with p_m violations in {prose.share(v_cv, n(base, 'CV_all'))}")
        + (f" ({v_word} than {best}'s {prose.share(v_best, n(base, best))})." if v_word != "as many"
           else f" (as many as {best}'s {prose.share(v_best, n(base, best))}, within sampling noise).")
    )  # fmt: skip
    if {"RSS_V2X_matched", "RSS_matched"} <= set(rss):
        v2x = r(base, "RSS_V2X_matched") - r(base, "RSS_matched")
        clear = prose.clearly(ci(base, "RSS_V2X_matched"), ci(base, "RSS_matched"))
        effect = (
            "changes success by less than sampling noise" if clear == 0 or v2x == 0
            else f"{'adds' if v2x > 0 else 'costs'} {abs(100 * v2x):.1f} percentage points of success"
        )  # fmt: skip
        text += (
            f" Within RSS, V2X (L1's promised bound as its brake_max) {effect} (RSS_V2X_matched "
            f"{prose.share(r(base, 'RSS_V2X_matched'))} vs RSS_matched {prose.share(r(base, 'RSS_matched'))})."
        )
    return text
