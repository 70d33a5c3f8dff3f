"""Cross-validation of SUMO against the built-in simulator (issue 11): the same sampled scenarios (``cell_rng`` and
``paper_scenarios``, as ``safelane simulate``), planner variant, nominal planner (expert) and shield settings, run by
``safelane.sim.simulate_batch`` and in SUMO (libsumo; collisions by SUMO's own list), for N in {1, 3, 10} x
a in {2, 4, 6} m/s².

* ``--traffic paper``: F and the leaders follow the paper's models in both; success and collision rates must agree
  within 95 % Wilson intervals (``agree``: each rate inside the other's interval). Because the scenarios are the
  same, the outcomes are also compared episode by episode (``differ``: episodes whose success differs).
* ``--traffic sumo``: F and the connected leaders are SUMO's Krauss drivers (who promised nothing): SUMO's measured
  rates, the built-in simulator's (paper traffic) beside them for reference only.

    .venv/bin/python benchmarks/sumo_crossval.py [--episodes 40] [--workers 2] [--traffic paper|sumo|both]
                                                 [--planner CV_all] [--seed 0] [--out DIR]

Each worker process runs its own SUMO (libsumo allows one simulation per process). Needs the sumo extra.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

LEADERS = (1, 3, 10)
DECELS = (2.0, 4.0, 6.0)


def _ci(k: int, n: int) -> tuple[float, float]:
    from safelane.sim import wilson_interval

    lo, hi = wilson_interval(k, n)
    return float(lo), float(hi)


def _fmt(k: int, n: int) -> str:
    lo, hi = _ci(k, n)
    return f"{k / n:.3f} [{lo:.3f}, {hi:.3f}]"


def _agree(k1: int, k2: int, n: int) -> bool:
    """Each rate inside the other's 95 % Wilson interval."""
    (lo1, hi1), (lo2, hi2) = _ci(k1, n), _ci(k2, n)
    return lo1 <= k2 / n <= hi1 and lo2 <= k1 / n <= hi2


def _markdown(head, rows) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=40, help="episodes per cell and traffic mode")
    ap.add_argument("--workers", type=int, default=2, help="processes, one SUMO each")
    ap.add_argument("--traffic", choices=("paper", "sumo", "both"), default="both")
    ap.add_argument("--planner", default="CV_all")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="write crossval.csv (one row per episode) here")
    args = ap.parse_args(argv)

    from safelane.integrations.sumo_cells import cell_scenarios, run_episodes
    from safelane.sim import simulate_batch

    cells = [(n, a) for n in LEADERS for a in DECELS]
    modes = ("paper", "sumo") if args.traffic == "both" else (args.traffic,)
    t0 = time.perf_counter()
    builtin, scenarios = {}, {}
    for n, a in cells:
        batch, scenarios[n, a] = cell_scenarios(args.planner, n, a, args.episodes, args.seed)
        builtin[n, a] = simulate_batch(batch, seed=args.seed).table  # expert planner, SimConfig(): as simulate
    t_builtin = time.perf_counter() - t0

    rows, timing = [], {}
    for mode in modes:
        flat = [sc for cell in cells for sc in scenarios[cell]]
        t1 = time.perf_counter()
        results = run_episodes(flat, planner=args.planner, traffic=mode, seed=args.seed, workers=args.workers)
        timing[mode] = (time.perf_counter() - t1, sum(r.steps for r in results), sum(r.wall_s for r in results))
        for i, r in enumerate(results):
            n, a = cells[i // args.episodes]
            ref = builtin[n, a].iloc[i % args.episodes]
            assert int(ref["scenario_id"]) == r.scenario_id
            row = r.results_row(args.planner)
            rows.append({**{f"sumo_{k}": v for k, v in row.items()}, "traffic": mode, "N": n, "a": a,
                         "scenario_id": r.scenario_id, "builtin_success": bool(ref["success"]),
                         "builtin_collision": bool(ref["collision"]), "builtin_breach": bool(ref["assumption_breach"]),
                         "builtin_completion_time_s": ref["completion_time_s"]})  # fmt: skip
    df = pd.DataFrame(rows)

    print(f"# SUMO vs the built-in simulator: {args.planner}, expert nominal planner, {args.episodes} episodes per "
          f"cell, seed {args.seed}, {args.workers} SUMO process(es); built-in {t_builtin:.0f} s, "
          + ", ".join(f"SUMO ({m}) {w:.0f} s" for m, (w, _, _) in timing.items()))  # fmt: skip
    ok = True
    for mode in modes:
        d = df[df.traffic == mode]
        print(f"\n## traffic = {mode}" + ("  (the built-in column: the paper's traffic, for reference)"
                                        if mode == "sumo" else ""))  # fmt: skip
        head = ["N", "a", "built-in success", "SUMO success", "agree", "differ", "built-in coll.", "SUMO coll.",
                "agree", "SUMO list", "breach b/S"]  # fmt: skip
        if mode == "sumo":
            head = [*head[:4], "SUMO coll.", "SUMO list", "promise viol.", "breach b/S"]
        table = []
        for (n, a), g in d.groupby(["N", "a"]):
            e = len(g)
            ks_b, ks_s = int(g.builtin_success.sum()), int(g.sumo_success.sum())
            kc_b, kc_s = int(g.builtin_collision.sum()), int(g.sumo_collision.sum())
            breach = f"{int(g.builtin_breach.sum())}/{int(g.sumo_assumption_breach.sum())}"
            if mode == "paper":
                agree_s, agree_c = _agree(ks_b, ks_s, e), _agree(kc_b, kc_s, e)
                ok &= agree_s and agree_c and int(g.sumo_sumo_collisions.sum()) == 0
                table.append([n, f"{a:g}", _fmt(ks_b, e), _fmt(ks_s, e), "yes" if agree_s else "NO",
                              int((g.builtin_success != g.sumo_success).sum()), _fmt(kc_b, e), _fmt(kc_s, e),
                              "yes" if agree_c else "NO", int(g.sumo_sumo_collisions.sum()), breach])  # fmt: skip
            else:
                table.append([n, f"{a:g}", _fmt(ks_b, e), _fmt(ks_s, e), _fmt(kc_s, e),
                              int(g.sumo_sumo_collisions.sum()), int(g.sumo_promise_violations.sum()),
                              breach])  # fmt: skip
        print(_markdown(head, table))
        diff = d[d.builtin_success != d.sumo_success]
        if mode == "paper" and len(diff):
            print("\nEpisodes whose success differs (built-in vs SUMO):")
            cols = ["N", "a", "scenario_id", "builtin_success", "sumo_success", "builtin_completion_time_s",
                    "sumo_completion_time_s", "builtin_breach", "sumo_assumption_breach", "sumo_breach_time_s",
                    "sumo_breach_follower", "sumo_collider", "sumo_victim"]  # fmt: skip
            print(diff[cols].to_string(index=False))
        wall, steps, ep_wall = timing[mode]
        print(f"\n{len(d)} episodes, {steps} steps: {steps / ep_wall:.0f} steps/s and {len(d) / ep_wall:.2f} "
              f"episodes/s per process; {len(d) / wall:.2f} episodes/s with {args.workers} process(es)")  # fmt: skip
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        df.to_csv(args.out / "crossval.csv", index=False)
        print(f"wrote {args.out / 'crossval.csv'}")
    hits = df[(df.traffic == "paper") & df.sumo_collision]
    print(f"\nSUMO's collision list, traffic paper (inside the assumptions): {int(hits.sumo_sumo_collisions.sum())} "
          f"entries -> {'PASS' if ok else 'FAIL (see above)'}")  # fmt: skip
    return 0 if ok or "paper" not in modes else 1


if __name__ == "__main__":
    raise SystemExit(main())
