"""The shield in SUMO: a reckless nominal policy (always merge at full authority) with and without the shield, L(N+1)
braking suddenly at a in {4, 6, 8} m/s², some episodes with an own-lane leader L0 (braking at U[0, 8] from
U[0, 3] s). Collisions by SUMO's own list (and our geometric cross-check), success rates, steps/s, and the parity of
our point-mass kinematics with SUMO's for a vehicle braking at constant deceleration.

    .venv/bin/python benchmarks/sumo_campaign.py [--episodes 210] [--traffic paper|sumo] [--workers 2] [--out DIR]

Each worker process runs its own SUMO (libsumo allows one simulation per process). Needs the sumo extra.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np
import pandas as pd

LEADERS = (1, 3, 5)


def _cell_scenarios(decel: float, episodes: int, own_share: float, seed: int):
    from safelane.integrations.sumo import sumo_scenarios

    per = -(-episodes // len(LEADERS))
    out = []
    for j, n in enumerate(LEADERS):
        out += sumo_scenarios(n, decel, per, seed=seed + 7919 * j + int(decel * 1000), own_share=own_share,
                              first_id=j * per)  # fmt: skip
    return out[:episodes]


def _work(job):
    decel, episodes, own_share, seed, traffic, shielded, part, parts = job
    from safelane.integrations.sumo import SumoRunner, reckless

    scenarios = _cell_scenarios(decel, episodes, own_share, seed)[part::parts]
    with SumoRunner(traffic=traffic, seed=seed, policy=reckless) as runner:  # the campaign's reckless merge
        table = runner.run_many(scenarios, shielded=shielded)
        if part == 0 and shielded and decel == 4.0:
            table.attrs["settings"] = runner.settings()
    return table


def _parity():
    from safelane.integrations.sumo_world import SumoWorld, braking_parity

    with SumoWorld() as world:
        return pd.DataFrame([braking_parity(world, v0, a) for v0, a in ((30.0, 8.0), (30.0, 6.0), (30.0, 4.0),
                                                                       (25.0, 7.7), (12.3, 5.1))])  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=210, help="episodes per braking level (N in {1, 3, 5})")
    ap.add_argument("--own-share", type=float, default=0.3, help="share of episodes with an L0 in the ego's lane")
    ap.add_argument("--traffic", choices=("paper", "sumo"), default="paper")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="write episodes.csv here")
    args = ap.parse_args(argv)
    pd.set_option("display.width", 200)
    pd.set_option("display.max_columns", 30)

    jobs = [(a, args.episodes, args.own_share, args.seed, args.traffic, sh, p, args.workers)
            for a in (4.0, 6.0, 8.0) for sh in (True, False) for p in range(args.workers)]  # fmt: skip
    t0 = time.perf_counter()
    ctx = mp.get_context("spawn")  # a fresh process per worker: one libsumo each
    with ctx.Pool(args.workers, maxtasksperchild=1) as pool:
        tables = pool.map(_work, jobs, chunksize=1)
    wall = time.perf_counter() - t0
    settings = next((t.attrs["settings"] for t in tables if "settings" in t.attrs), None)
    df = pd.concat(tables, ignore_index=True)

    print(f"# SUMO campaign: traffic={args.traffic}, {args.episodes} episodes per braking level (N in {LEADERS}), "
          f"L0 share {args.own_share}, seed {args.seed}, {args.workers} worker(s), {wall:.0f} s wall")  # fmt: skip
    print(f"SUMO settings read back: {settings}")
    print("\n## Per braking level (collisions by SUMO's list; overlap = our geometric cross-check)")
    g = df.groupby(["shielded", "decel"])
    summary = pd.DataFrame({
        "episodes": g.size(),
        "collisions": g.collided.sum(),
        "overlaps": g.geometric_overlap.sum(),
        "success": g.success.mean().round(3),
        "with_L0": g.has_l0.sum(),
        "L0_collisions": g.apply(lambda t: int((t.collided & (t.victim == "L0")).sum()), include_groups=False),
        "breach": g.breach.mean().round(3),
        "promise_violations": g.promise_violations.sum(),
        "steps_per_s": (g.steps.sum() / g.wall_s.sum()).round(0),
    })  # fmt: skip
    print(summary.to_string())
    print("\n## With and without L0 (shielded)")
    sh = df[df.shielded].groupby(["decel", "has_l0"])
    print(pd.DataFrame({"episodes": sh.size(), "collisions": sh.collided.sum(), "success": sh.success.mean().round(3)})
          .to_string())  # fmt: skip
    print("\n## Collisions classified (SUMO's list: collider -> victim, lane, the ego's lateral phase)")
    hits = df[df.collided]
    if len(hits):
        print(hits.groupby(["shielded", "collider", "victim", "lane", "phase"]).size().rename("n").to_string())
    else:
        print("none")
    shielded_hits = hits[hits.shielded]
    if len(shielded_hits):
        print("\nShielded collisions (every one):")
        print(shielded_hits[["scenario_id", "n_leaders", "decel", "has_l0", "own_decel", "collider", "victim", "lane",
                             "phase", "t_collision_s", "breach"]].to_string())  # fmt: skip
    geo_only = df[df.geometric_overlap & ~df.collided]
    print(f"\nGeometric overlaps SUMO's list did not report: {len(geo_only)}")
    print("\n## Parity: a vehicle braking at constant deceleration, SUMO (ballistic, speed commands) vs point mass")
    parity = _parity()
    print(parity.to_string())
    moving_ok = (parity.max_pos_err_moving_m < 1e-9).all()
    ok = moving_ok and (parity.max_pos_err_stopped_m <= parity.stop_bound_m + 1e-9).all()
    print(f"tolerance: 1e-9 m while moving, decel*dt^2/8 at the stopping step -> {'PASS' if ok else 'FAIL'}")
    print(f"\nTotal: {len(df)} episodes, {int(df.steps.sum())} steps, "
          f"{df.steps.sum() / df.wall_s.sum():.0f} steps/s per process (wall time incl. SUMO reloads)")  # fmt: skip
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        df.to_csv(args.out / "episodes.csv", index=False)
        print(f"wrote {args.out / 'episodes.csv'}")
    n_bad = int(df[df.shielded].collided.sum())
    return 0 if n_bad == 0 or args.traffic == "sumo" or np.isnan(n_bad) else 1


if __name__ == "__main__":
    raise SystemExit(main())
