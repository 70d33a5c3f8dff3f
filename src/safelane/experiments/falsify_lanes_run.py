"""The multi-lane falsifier's campaign: batches of :mod:`.falsify_lanes` scenarios, in one or several processes, and
the report that counts them inside and outside the assumptions (``safelane falsify --world lanes``)."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .falsify_lanes import LaneWorld, Outcome, draw, simulate


@dataclass
class LaneReport:
    """Counts over every simulated row, split by inside / outside the assumptions."""

    generated: int = 0
    not_started: int = 0  # rows whose start is not inside the assumptions (not judged)
    seconds: float = 0.0
    counts: dict = field(default_factory=dict)
    min_ratio_inside: float = float("inf")
    #: Every scenario inside the assumptions with a collision or a ``p_m`` violation: where to replay it
    #: (``default_rng([seed, stream, batch])``, row ``row`` of a batch of ``batch_size``) and what happened.
    failures: list = field(default_factory=list)

    def add(self, out: Outcome, where: dict | None = None) -> list[dict]:
        """Count ``out``'s rows; ``where`` (``seed``, ``stream``, ``batch``, ``batch_size``) locates the batch.
        Returns the failures inside the assumptions it adds."""
        found = []
        for r in np.flatnonzero(out.inside & (out.collided | out.violated)):
            found.append({**(where or {}), "row": int(r), "collision": bool(out.collided[r]),
                          "p_m_violation": bool(out.violated[r]),
                          "ego_responsible": bool(out.ego_collision[r] | out.ego_violation[r])})  # fmt: skip
        self.failures.extend(found)
        self.generated += len(out.inside)
        self.not_started += int((~out.started).sum())
        for where, rows in (("inside", out.inside), ("outside", out.started & ~out.inside)):
            c = self.counts.setdefault(where, dict.fromkeys(
                ("scenarios", "collisions", "ego_responsible_collisions", "p_m_violations",
                 "ego_responsible_p_m_violations", "entries", "breaches_flagged", "completed"), 0))  # fmt: skip
            c["scenarios"] += int(rows.sum())
            c["collisions"] += int((out.collided & rows).sum())
            c["ego_responsible_collisions"] += int((out.ego_collision & rows).sum())
            c["p_m_violations"] += int((out.violated & rows).sum())
            c["ego_responsible_p_m_violations"] += int((out.ego_violation & rows).sum())
            c["entries"] += int(out.entries[rows].sum())
            c["breaches_flagged"] += int((out.breached & rows).sum())
            c["completed"] += int((out.completed & rows).sum())
        if out.inside.any():
            self.min_ratio_inside = min(self.min_ratio_inside, float(out.min_ratio[out.inside].min()))
        return found

    def text(self) -> str:
        lines = [f"multi-lane falsifier: {self.generated:,} scenarios drawn in {self.seconds:.0f} s, "
                 f"{self.not_started:,} not starting inside the assumptions (not judged)"]
        names = {"inside": "inside the assumptions", "outside": "outside (an entrant broke the entering rule)"}
        for where, c in self.counts.items():
            lines.append(f"  {names[where]}: " + ", ".join(f"{k} {v:,}" for k, v in c.items()))
        lines.append(f"  smallest |dx|/p_m inside (laterally conflicting samples): {self.min_ratio_inside:.6f}")
        lines.extend(f"  failure inside: {_where(f)}" for f in self.failures)
        return "\n".join(lines)


def _where(f: dict) -> str:
    kinds = [k for k in ("collision", "p_m_violation") if f[k]]
    return (f"seed {f.get('seed')} stream {f.get('stream')} batch {f.get('batch')} (size {f.get('batch_size')}) row "
            f"{f['row']}: {' and '.join(kinds)}, {'the ego' if f['ego_responsible'] else 'the other'} responsible")


def run(scenarios: int, seed: int = 0, batch_size: int = 2048, world: LaneWorld | None = None, stream: int = 0,
        minutes: float = 0.0, on_batch=None) -> LaneReport:  # fmt: skip
    """Batches of ``batch_size`` rows until ``scenarios`` rows and ``minutes`` have passed; batch ``i`` draws from
    ``default_rng([seed, stream, i])``."""
    world = world or LaneWorld()
    report, t0, i = LaneReport(), time.perf_counter(), 0
    while report.generated < scenarios or time.perf_counter() - t0 < 60.0 * minutes:
        spec = draw(np.random.default_rng([seed, stream, i]), batch_size, world.params)
        where = {"seed": seed, "stream": stream, "batch": i, "batch_size": batch_size}
        for f in report.add(simulate(spec, world), where):  # at once: a long campaign can be stopped on it
            print(f"multi-lane falsifier: failure inside: {_where(f)}", file=sys.stderr, flush=True)
        report.seconds = time.perf_counter() - t0
        i += 1
        if on_batch is not None:
            on_batch(report)
    return report


def _stream(args) -> LaneReport:
    scenarios, seed, batch_size, world, stream, minutes = args
    return run(scenarios, seed, batch_size, world, stream, minutes)


def run_streams(scenarios: int, seed: int = 0, batch_size: int = 2048, world: LaneWorld | None = None,
                minutes: float = 0.0, workers: int = 1) -> LaneReport:  # fmt: skip
    """``workers`` independent streams (stream ``w`` draws from ``default_rng([seed, w, i])``) in as many processes,
    ``scenarios`` split between them; their reports merged (the same for the same ``workers``)."""
    if workers <= 1:
        return run(scenarios, seed, batch_size, world, 0, minutes)
    from concurrent.futures import ProcessPoolExecutor

    share = -(-scenarios // workers)
    jobs = [(share, seed, batch_size, world or LaneWorld(), w, minutes) for w in range(workers)]
    with ProcessPoolExecutor(workers) as pool:
        parts = list(pool.map(_stream, jobs))
    out = LaneReport(generated=sum(p.generated for p in parts), not_started=sum(p.not_started for p in parts),
                     seconds=max(p.seconds for p in parts))  # fmt: skip
    for p in parts:
        for where, c in p.counts.items():
            mine = out.counts.setdefault(where, dict.fromkeys(c, 0))
            for k, v in c.items():
                mine[k] += v
        out.min_ratio_inside = min(out.min_ratio_inside, p.min_ratio_inside)
        out.failures.extend(p.failures)
    return out


__all__ = ["LaneReport", "run", "run_streams"]
