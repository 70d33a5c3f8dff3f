"""The paper's shield vs the extended shield in the realistic world (issue 17, docs/real_roads.md).

For every published Table 1 cell (4 variants × the published (N, a) pairs) and each world — the ego's own lane with a
braking leader L0, sensing errors, actuation delay 0.2 s, all three — this runs the paper's shield (no L0, exact
states, no delay: ``shield_own_lane/sensing/delay = False``) and the extended shield on the same scenarios (common
random numbers), both on the ``safe`` preset, and prints collision and p_m-violation rates; then the extension's cost
in success rate per cell (the extended shield in the realistic world vs the safe shield in the paper's world).

    python benchmarks/real_roads.py [--samples 100] [--seed 0] [--out results/real_roads]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

from safelane.experiments.calibration import published_cells
from safelane.experiments.grid import run_cells
from safelane.sim.preset import load_preset

WORLDS = {
    "L0 braking": dict(own_lane=True),
    "sensing error": dict(sensing_error=True, sensing_edge_share=0.5),
    "delay 0.2 s": dict(actuation_delay_s=0.2),
    "all three": dict(own_lane=True, sensing_error=True, sensing_edge_share=0.5, actuation_delay_s=0.2),
}
PAPER_SHIELD = dict(shield_own_lane=False, shield_sensing=False, shield_delay=False)


def run(samples: int, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    preset = load_preset("safe")
    cells = published_cells()
    rows, per_cell = [], {}

    def table(update: dict) -> pd.DataFrame:
        cfg = preset.sim.model_copy(update=update)
        return run_cells(cells, samples, seed, params=preset.params, config=cfg, nominal=preset.nominal())

    t0 = time.perf_counter()
    base = table({})
    rows.append(_rates("paper's world", "safe shield", base))
    per_cell["paper world, safe shield"] = base.groupby("cell").success.mean()
    for world, update in WORLDS.items():
        for shield, extra in (("paper's shield", PAPER_SHIELD), ("extended shield", {})):
            t = table({**update, **extra})
            rows.append(_rates(world, shield, t))
            if world == "all three" and shield == "extended shield":
                per_cell["realistic world, extended shield"] = t.groupby("cell").success.mean()
    print(f"[{time.perf_counter() - t0:.0f} s]")
    cost = pd.DataFrame(per_cell)
    cost.index = [f"{c.planner} N={c.n_leaders} a={c.decel:g}" for c in cells]
    cost["cost"] = cost["paper world, safe shield"] - cost["realistic world, extended shield"]
    return pd.DataFrame(rows), cost


def _rates(world: str, shield: str, t: pd.DataFrame) -> dict:
    return dict(world=world, shield=shield, scenarios=len(t), collision_rate=t.collision.mean(),
                violation_rate=t.safety_violation.mean(), success=t.success.mean(),
                initial_unsafe=(~t.initial_safe).mean())  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=100, help="scenarios per cell")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("results/real_roads"))
    args = ap.parse_args()
    rates, cost = run(args.samples, args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    rates.to_csv(args.out / "rates.csv", index=False)
    cost.to_csv(args.out / "success_cost.csv")
    pd.set_option("display.width", 160)
    print(rates.to_string(index=False, float_format=lambda x: f"{x:.4f}"))
    print()
    print(cost.to_string(float_format=lambda x: f"{x:.3f}"))
    print(f"\nmean success cost per cell: {cost['cost'].mean():.3f} (largest {cost['cost'].max():.3f})")


if __name__ == "__main__":
    main()
