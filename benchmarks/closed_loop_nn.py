# ruff: noqa: E402  (the BLAS thread settings below must precede the first NumPy import)
"""Closed loop of issue 4: the shipped neural planner + supervisor against its teacher + supervisor.

Cells: ``CV_all``, the paper's sampler (L1..LN connected, F connected, ego ``U[29, 31]`` m/s, traffic 30 m/s,
``δp ~ U[17, 22]`` m), N ∈ {1, 3, 10} × ``a_x_N+1_d`` ∈ {2, 3, 4, 5, 6} m/s², 1,000 scenarios per cell, default
``Params()`` (the shipped model was trained under them), p_v = 0, observed assessment. Both planners see the same
scenarios (``safelane.experiments.grid.run_cells``: common random numbers, one batch for the whole grid).

Criterion (issue 4, "what it must show" 2): in every cell the network's success rate is at most 3 points below
the teacher's, and neither planner collides. Success rates come with 95 % Wilson intervals; Δ is
``success(NN) − success(teacher)`` in percentage points.

Run with ``python benchmarks/closed_loop_nn.py [--samples 1000] [--seed 0] [--model PATH] [--csv PATH]``. Prints
a Markdown table and the verdict; asserts nothing.
"""

from __future__ import annotations

import os

# One BLAS thread: the planners multiply many small matrices, where a multi-threaded OpenBLAS on a shared
# machine spends most of its time synchronising (about 6x slower end to end on 2 busy cores).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import time

import pandas as pd

from safelane import Params
from safelane.experiments.grid import Cell, run_cells
from safelane.planners import MLPPlanner, get_nominal
from safelane.sim import SimConfig, wilson_interval

LEADERS = (1, 3, 10)
DECELS = (2.0, 3.0, 4.0, 5.0, 6.0)
TOLERANCE_POINTS = 3.0


def run(planner, cells: list[Cell], samples: int, seed: int) -> tuple[pd.DataFrame, float]:
    """Per-cell counts for one nominal planner (supervisor on) and the wall time [s]."""
    start = time.perf_counter()
    table = run_cells(cells, samples, seed, params=Params(), config=SimConfig(), nominal=planner)
    seconds = time.perf_counter() - start
    grouped = table.groupby(["n_leaders", "decel"], sort=True)
    out = pd.DataFrame(
        {
            "samples": grouped.size(),
            "success": grouped["success"].sum(),
            "collision": grouped["collision"].sum(),
            "safety_violation": grouped["safety_violation"].sum(),
            "completion_time_s": grouped["completion_time_s"].mean(),
        }
    )
    return out, seconds


def compare(nn: pd.DataFrame, teacher: pd.DataFrame) -> pd.DataFrame:
    """One row per cell: both success rates with Wilson intervals, Δ [points], collisions, violations."""
    out = pd.DataFrame(index=nn.index)
    out["samples"] = nn["samples"]
    for name, t in (("nn", nn), ("teacher", teacher)):
        lo, hi = wilson_interval(t["success"].to_numpy(), t["samples"].to_numpy())
        out[f"success_{name}"] = t["success"] / t["samples"]
        out[f"success_{name}_lo"], out[f"success_{name}_hi"] = lo, hi
        out[f"collision_{name}"] = t["collision"]
        out[f"violation_{name}"] = t["safety_violation"]
        out[f"completion_time_{name}_s"] = t["completion_time_s"]
    out["delta_points"] = 100.0 * (out["success_nn"] - out["success_teacher"])
    out["within_tolerance"] = out["delta_points"] >= -TOLERANCE_POINTS
    return out.reset_index()


def markdown(cmp: pd.DataFrame) -> str:
    def rate(r, name):
        return f"{r[f'success_{name}']:.3f} [{r[f'success_{name}_lo']:.3f}, {r[f'success_{name}_hi']:.3f}]"

    lines = [
        "| N | a_x,N+1,d | success NN + sup. [95 % CI] | success teacher + sup. [95 % CI] | Δ [points] "
        "| collisions NN / teacher | p_m violations NN / teacher | completion [s] NN / teacher | ≤ 3 pts |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for _, r in cmp.iterrows():
        lines.append(
            f"| {r['n_leaders']} | {r['decel']:g} | {rate(r, 'nn')} | {rate(r, 'teacher')} | {r['delta_points']:+.1f} "
            f"| {r['collision_nn']} / {r['collision_teacher']} | {r['violation_nn']} / {r['violation_teacher']} "
            f"| {r['completion_time_nn_s']:.2f} / {r['completion_time_teacher_s']:.2f} "
            f"| {'yes' if r['within_tolerance'] else '**no**'} |"
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1_000, help="scenarios per cell")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--model", default=None, help="an MLP .npz to evaluate instead of the shipped one")
    ap.add_argument("--csv", default=None, help="also write the per-cell comparison to this CSV")
    args = ap.parse_args(argv)
    cells = [Cell("CV_all", n, d) for n in LEADERS for d in DECELS]
    nn_planner = MLPPlanner.load(args.model) if args.model else get_nominal("mlp")
    print(
        f"closed loop, CV_all, paper sampler, N in {LEADERS}, a_x_N+1_d in {DECELS}, {args.samples} scenarios per "
        f"cell, seed {args.seed}, Params() defaults, supervisor on, model {args.model or 'shipped mlp_default'}\n"
    )
    nn, t_nn = run(nn_planner, cells, args.samples, args.seed)
    teacher, t_teacher = run(get_nominal("teacher"), cells, args.samples, args.seed)
    cmp = compare(nn, teacher)
    print(markdown(cmp))
    if args.csv:
        cmp.to_csv(args.csv, index=False)
    n_total = int(cmp["samples"].sum())
    failing = cmp[~cmp["within_tolerance"]]
    print(
        f"\nwall time: NN {t_nn:.1f} s, teacher {t_teacher:.1f} s ({n_total} scenarios each)\n"
        f"largest shortfall below the teacher: {max(0.0, -cmp['delta_points'].min()):.1f} points; "
        f"cells more than {TOLERANCE_POINTS:g} points below the teacher: {len(failing)}"
        + "".join(f"\n  N={r.n_leaders}, a_x_N+1_d={r.decel:g}: {r.delta_points:+.1f}" for r in failing.itertuples())
        + f"\ncollisions: NN {int(cmp['collision_nn'].sum())}, teacher {int(cmp['collision_teacher'].sum())}; "
        f"p_m violations: NN {int(cmp['violation_nn'].sum())}, teacher {int(cmp['violation_teacher'].sum())}"
    )


if __name__ == "__main__":
    main()
