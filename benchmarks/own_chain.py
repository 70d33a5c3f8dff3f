"""What a connected own lane buys (docs/real_roads.md, "A connected own lane").

The ``realistic`` preset (the others brake up to 9.5 m/s², sensing errors, 0.2 s delay, L0 in the ego's own lane)
on every published Table 1 cell, with 0, 1, 2 and 3 connected vehicles from L0 on (``SimConfig.own_lane_connected``;
0 is the preset as it ships: one non-connected L0). The same scenarios in every column (common random numbers: the
target lane, L0 and its braking are the same draws; the connected vehicles ahead of L0 are added, each promising
0.5 m/s² and braking at it from a random instant, and the non-connected vehicle ahead of them brakes as L0 does
without them). Prints success, the collision and ``p_m``-violation rates (every row, and the rows that start inside
the assumptions), how often the own lane's vehicles ran into each other, and the success per variant.

    python benchmarks/own_chain.py [--samples 100] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import pandas as pd

from safelane.experiments.calibration import published_cells
from safelane.experiments.grid import run_cells
from safelane.sim.preset import load_preset


def run(samples: int, seed: int, connected: list[int]) -> pd.DataFrame:
    preset = load_preset("realistic")
    cells = published_cells()
    rows = []
    for n in connected:
        t0 = time.perf_counter()
        cfg = preset.sim.model_copy(update={"own_lane_connected": n})
        t = run_cells(cells, samples, seed, params=preset.params, config=cfg, nominal=preset.nominal())
        inside = t[t.initial_safe]
        pair = t.own_lane_leader_collision.mean() if "own_lane_leader_collision" in t else 0.0
        rows.append(dict(connected=n, scenarios=len(t), success=t.success.mean(), collision=t.collision.mean(),
                         violation=t.safety_violation.mean(), inside=len(inside),
                         collision_inside=inside.collision.mean(), violation_inside=inside.safety_violation.mean(),
                         own_lane_pair_collision=pair, **t.groupby("planner").success.mean().to_dict(),
                         wall_s=time.perf_counter() - t0))  # fmt: skip
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=100, help="scenarios per cell")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--connected", type=int, nargs="+", default=[0, 1, 2, 3])
    args = ap.parse_args()
    table = run(args.samples, args.seed, args.connected)
    pd.set_option("display.width", 200)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.4f}"))


if __name__ == "__main__":
    main()
