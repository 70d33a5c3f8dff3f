# ruff: noqa: E402  (the BLAS thread settings below must precede the first NumPy import)
"""Why the supervisor exists (issue 4, "what it must show" 3): nominal planners with and without it.

Planners: the shipped network (``mlp``) and networks of the same architecture and normalisation with random
weights (``safelane.planners.nn.with_random_weights``, seeds 0, 1, … from ``numpy.random.default_rng``), each
with the safety supervisor and without it (``SimConfig(supervised=False)``: the nominal accelerations are
executed as proposed, clipped to the mechanical limits).

Scenario sets, all ``CV_all`` with p_v = 0 and ``a_x_N+1_d ≤ a_x_d`` (the paper's assumptions):

* **stress grid** (the per-cell table): the paper's sampler with N ∈ {0, 1, 3, 10} × ``a_x_N+1_d`` ∈ {2, 4, 6, 8}
  m/s² and mixed traffic — half the followers connected (collaborative, and saying so), a quarter non-connected
  collaborative, a quarter non-connected aggressive; 20 % of the connected leaders human-driven. N = 0 means L1
  itself is the non-connected vehicle that brakes suddenly.
* **paper grid**: exactly the cells of ``benchmarks/closed_loop_nn.py`` (F connected, N ∈ {1, 3, 10},
  ``a_x_N+1_d`` ∈ {2..6}).

The follower's type is known to the supervisor (``assessment="truth"``: the paper's guarantee assumes a correct
aggressiveness assessment). ``--observed`` adds a pass of the supervised planners with the real, observed
assessment (no guarantee). Collision rates come with 95 % Wilson intervals. A collision is physical contact
(centre distance below a vehicle length while laterally overlapping); a ``p_m`` violation a gap below the
safety margin.

Run with ``python benchmarks/supervisor_ablation.py [--samples 1000] [--random-nets 3] [--seed 0] [--observed]``.
Prints Markdown tables; asserts nothing.
"""

from __future__ import annotations

import os

# One BLAS thread: small matrix products on a shared machine (see benchmarks/closed_loop_nn.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import time

import numpy as np
import pandas as pd

from safelane import Params
from safelane.experiments.grid import Cell, run_cells
from safelane.planners import get_nominal
from safelane.planners.nn import with_random_weights
from safelane.sim import ScenarioConfig, SimConfig, wilson_interval

STRESS_LEADERS = (0, 1, 3, 10)
STRESS_DECELS = (2.0, 4.0, 6.0, 8.0)
PAPER_LEADERS = (1, 3, 10)
PAPER_DECELS = (2.0, 3.0, 4.0, 5.0, 6.0)
MIXED_TRAFFIC = ScenarioConfig(follower_connected_share=0.5, follower_aggressive_share=0.5, human_share=0.2)
COUNTS = ("collision", "safety_violation", "success")


def scenario_sets() -> dict[str, tuple[list[Cell], ScenarioConfig | None]]:
    return {
        "stress grid": ([Cell("CV_all", n, d) for n in STRESS_LEADERS for d in STRESS_DECELS], MIXED_TRAFFIC),
        "paper grid": ([Cell("CV_all", n, d) for n in PAPER_LEADERS for d in PAPER_DECELS], None),
    }


def follower_type(table: pd.DataFrame) -> pd.Series:
    return pd.Series(
        np.where(
            table["follower_connected"],
            "connected",
            np.where(table["follower_aggressive"], "aggressive", "non-conn. collab."),
        ),
        index=table.index,
    )


def run_all(args) -> pd.DataFrame:
    """Per-scenario rows of every (scenario set, planner, supervisor, assessment) run, tagged by columns."""
    prm = Params()
    base = get_nominal("mlp")
    planners = {"NN": [base]}
    planners["random"] = [with_random_weights(base, np.random.default_rng(s)) for s in range(args.random_nets)]
    modes = [("off", "truth"), ("on", "truth")] + ([("on", "observed")] if args.observed else [])
    tables = []
    for set_name, (cells, scenario) in scenario_sets().items():
        for label, nets in planners.items():
            for supervisor, assessment in modes:
                cfg = SimConfig(supervised=supervisor == "on", assessment=assessment)
                start = time.perf_counter()
                for k, net in enumerate(nets):
                    t = run_cells(
                        cells, args.samples, args.seed, params=prm, config=cfg, scenario=scenario, nominal=net
                    )
                    t["net"] = k
                    t["set"], t["nominal"], t["supervisor"], t["assessment"] = set_name, label, supervisor, assessment
                    t["f_type"] = follower_type(t)
                    tables.append(t)
                print(
                    f"  {set_name:<12} {label:<7} supervisor {supervisor:<3} assessment {assessment:<8} "
                    f"{len(nets) * len(cells) * args.samples:>6} scenarios  {time.perf_counter() - start:6.1f} s",
                    flush=True,
                )
    return pd.concat(tables, ignore_index=True)


def rate(k: int, n: int) -> str:
    lo, hi = wilson_interval(k, n)
    return f"{k} / {n} = {k / n:.4f} [{float(lo):.4f}, {float(hi):.4f}]"


def summary_table(t: pd.DataFrame) -> str:
    lines = [
        "| scenarios | nominal planner | supervisor | assessment | collisions / scenarios = rate [95 % CI] "
        "| p_m violations | success |",
        "|---|---|---|---|---|---|---|",
    ]
    for (set_name, nominal, sup, assess), g in t.groupby(["set", "nominal", "supervisor", "assessment"], sort=False):
        k = int(g["collision"].sum())
        lines.append(
            f"| {set_name} | {nominal} | {sup} | {assess} | {rate(k, len(g))} | {int(g['safety_violation'].sum())} "
            f"| {g['success'].mean():.3f} |"
        )
    return "\n".join(lines)


def cell_table(t: pd.DataFrame) -> str:
    """Stress grid, truth assessment: collisions per cell for the four planner × supervisor combinations."""
    s = t[(t["set"] == "stress grid") & (t["assessment"] == "truth")]
    combos = [("NN", "off"), ("NN", "on"), ("random", "off"), ("random", "on")]
    counts = s.groupby(["n_leaders", "decel", "nominal", "supervisor"])["collision"].agg(["sum", "size"])
    head = " | ".join(f"{n} sup. {sup}" for n, sup in combos)
    lines = [f"| N | a_x,N+1,d | {head} |", "|---|---|" + "---|" * len(combos)]
    for n in STRESS_LEADERS:
        for d in STRESS_DECELS:
            cols = [f"{int(counts.loc[(n, d, *c), 'sum'])} / {int(counts.loc[(n, d, *c), 'size'])}" for c in combos]
            lines.append(f"| {n} | {d:g} | " + " | ".join(cols) + " |")
    return "\n".join(lines)


def by_follower_table(t: pd.DataFrame) -> str:
    """Stress grid, unsupervised NN: collisions by the follower's type."""
    s = t[(t["set"] == "stress grid") & (t["supervisor"] == "off") & (t["assessment"] == "truth")]
    lines = ["| nominal planner (sup. off) | follower | collisions / scenarios = rate [95 % CI] |", "|---|---|---|"]
    for (nominal, f), g in s.groupby(["nominal", "f_type"], sort=True):
        lines.append(f"| {nominal} | {f} | {rate(int(g['collision'].sum()), len(g))} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1_000, help="scenarios per cell")
    ap.add_argument("--random-nets", type=int, default=3, help="random-weight networks (seeds 0, 1, …)")
    ap.add_argument("--seed", type=int, default=0, help="scenario seed")
    ap.add_argument("--observed", action="store_true", help="also run the supervised planners, observed assessment")
    args = ap.parse_args(argv)
    print(
        f"supervisor ablation: {args.samples} scenarios per cell, {args.random_nets} random-weight networks, "
        f"scenario seed {args.seed}, CV_all, p_v = 0, Params() defaults\n"
    )
    start = time.perf_counter()
    t = run_all(args)
    print(f"\ntotal {time.perf_counter() - start:.0f} s\n")
    print(summary_table(t), "\n")
    print("Stress grid, assessment = truth, collisions / scenarios per cell:\n")
    print(cell_table(t), "\n")
    print(by_follower_table(t))


if __name__ == "__main__":
    main()
