"""What the multi-lane world costs: success per Table 1 cell, the paper's two lanes against the same scenarios with
traffic in the lanes beside (``SimConfig.neighbours``; :mod:`safelane.sim.neighbours`).

The neighbours keep their lanes, so every difference is the price of the shield's world model not knowing that they
will (docs/safety.md, rules 4 and 5): the same cell and seed draw the same scenarios in both worlds, and the
collision and ``p_m`` columns show that the neighbours change no outcome but the ego's own decisions.

    python -m safelane.experiments.lane_cost --preset paper --samples 400 --seed 0 --workers 2
"""

from __future__ import annotations

import argparse
import time

from .paper_data import DECELS, PLANNERS

#: Table 1's N values.
TABLE1_N = (1, 3, 10)


def cost_table(preset: str = "paper", samples: int = 400, seed: int = 0, workers: int = 1, n_values=TABLE1_N,
               decels=DECELS, planners=PLANNERS):  # fmt: skip
    """One row per cell: success, collision and ``p_m`` violation rates in the paper's world and with neighbours."""
    import pandas as pd

    from ..sim.engine import simulate
    from ..sim.preset import load_preset

    chosen = load_preset(preset)
    rows = []
    for n in n_values:
        for decel in decels:
            for planner in planners:
                row = {"n_leaders": n, "decel": decel, "planner": planner}
                for world, neighbours in (("paper_world", False), ("neighbours", True)):
                    config = chosen.sim.model_copy(update={"neighbours": neighbours})
                    got = simulate(planner, n, decel, samples, seed, preset=chosen, config=config,
                                   workers=workers).summary().iloc[0]  # fmt: skip
                    row[f"{world}_success"] = float(got["success_rate"])
                    row[f"{world}_collision"] = float(got["collision_rate"])
                    row[f"{world}_pm_violation"] = float(got["safety_violation_rate"])
                row["cost"] = row["paper_world_success"] - row["neighbours_success"]
                rows.append(row)
    return pd.DataFrame(rows)


def text(table) -> str:
    """The table as Markdown: success in both worlds and the cost per cell, then the safety columns' maxima."""
    lines = ["| N | a | planner | paper world | with neighbours | cost |", "|---|---|---|---|---|---|"]
    for r in table.itertuples():
        lines.append(f"| {r.n_leaders} | {r.decel:g} | {r.planner} | {r.paper_world_success:.3f} | "
                     f"{r.neighbours_success:.3f} | {r.cost:+.3f} |")  # fmt: skip
    worst = {c: table[c].max() for c in table.columns if c.endswith(("_collision", "_pm_violation"))}
    lines.append("")
    lines.append("largest rates over the cells: " + ", ".join(f"{c} {v:.4f}" for c, v in worst.items()))
    lines.append(f"mean cost over the cells: {table['cost'].mean():+.3f}")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="paper")
    ap.add_argument("--samples", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--csv", default=None, help="Also write the table here.")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    table = cost_table(args.preset, args.samples, args.seed, args.workers)
    print(f"lane cost: preset {args.preset}, {args.samples} scenarios per cell and world, seed {args.seed}, "
          f"{time.perf_counter() - t0:.0f} s")  # fmt: skip
    print(text(table))
    if args.csv:
        table.to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
