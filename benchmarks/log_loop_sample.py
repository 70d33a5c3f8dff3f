"""Closed loop on the log over the shipped US-101 sample (docs/real_traffic.md, "Closed loop on the log"): every
recorded lane change redone by the preset's planner under the shield, the others replayed as recorded. Prints the
per-event table and the summary row as Markdown; a few seconds.

    .venv/bin/python benchmarks/log_loop_sample.py [--preset realistic] [--nominal expert|mlp] [--lead-s 3.0]
"""

from __future__ import annotations

import argparse
import time

from safelane.recorded.log_loop import run_log_loop, summary
from safelane.recorded.store import load_recording, sample_paths


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="realistic")
    parser.add_argument("--nominal", default="expert")
    parser.add_argument("--lead-s", type=float, default=3.0)
    parser.add_argument("--horizon-s", type=float, default=8.0)
    args = parser.parse_args()
    recordings = [load_recording(p) for p in sample_paths()]
    start = time.perf_counter()
    table = run_log_loop(recordings, preset=args.preset, nominal=args.nominal, lead_s=args.lead_s,
                         horizon_s=args.horizon_s)  # fmt: skip
    wall = time.perf_counter() - start
    table["source"] = [s.rsplit("/", 1)[-1] for s in table["source"]]
    cols = ["source", "vehicle_id", "start_t", "horizon_s", "human_time_s", "completed", "time_s", "n_hesitate",
            "n_abort", "initial_safe", "collision", "collision_blame", "pm_ego", "pm_other"]  # fmt: skip
    print(table[cols].to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    print()
    s = summary(table)
    print("| events | completed | time to complete, median / worst [s] | the human's, same events | collisions "
          "(ego's) | p_m violations ego / other | events aborting | handed over unsafe |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    print(f"| {s['events']} | {s['completed']} | {s['median_time_s']:.2f} / {s['worst_time_s']:.2f} | "
          f"{s['human_median_time_s_same']:.2f} / {s['human_worst_time_s_same']:.2f} | {s['collisions']} "
          f"({s['collisions_ego']}) | {s['pm_ego']} / {s['pm_other']} | {s['events_aborting']} | "
          f"{s['handed_over_unsafe']} |")  # fmt: skip
    print(f"\n{args.preset} preset, nominal {args.nominal}, lead {args.lead_s} s: {wall:.1f} s")


if __name__ == "__main__":
    main()
