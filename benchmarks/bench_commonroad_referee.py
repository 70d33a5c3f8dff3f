"""CommonRoad out and the drivability checker as referee: episodes of the built-in simulator, highway-env and SUMO,
shielded and unshielded, each exported to a CommonRoad XML file, read back, and refereed by commonroad_dc beside the
host's own collision verdict (safelane.integrations.commonroad*; docs/integrations.md, "CommonRoad").

    .venv/bin/python benchmarks/bench_commonroad_referee.py                  # 1,020 episodes
    .venv/bin/python benchmarks/bench_commonroad_referee.py --simulator 40 --highway 6 --sumo 6   # a quick look

Runs (all in this process, one after the other):

* simulator — the paper's sampler. Shielded: the expert (N ∈ {1, 3, 5}, a ∈ {4, 6, 8}) and reckless merges with
  an L0 in the ego's lane; unshielded (``SimConfig(supervised=False)``): reckless merges of random strength
  (``RecklessMerge``, a_x ∈ U[−4, 3] m/s², lateral gain U[0.2, 1]) with an L0, and the oscillating adversary;
* highway-env — the lane-change scene (a ∈ {4, 6, 8}, an L0 braking in every other episode) with the reckless
  full-authority policy of benchmarks/highway_campaign.py, without and with the shield;
* SUMO — the paper's sampler (N ∈ {1, 3}, a = 6, an L0 in 30 % of the episodes) with ``sumo.reckless``, without and
  with the shield.

Printed: per run, the host's and the checker's collision counts, both collide / both clear / disagreements; every
disagreement with its reason, and every agreement that needed the referee's closer look (a contact between the
samples, or behind highway-env's collision response); whether the verdict from the file equals the
verdict from the scenario in memory; timings per stage.
"""

from __future__ import annotations

import argparse
import collections
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np


def simulator_runs(n: int, seed: int):
    """``(label, episodes)`` pairs of the built-in simulator; ``n`` episodes in all."""
    from safelane.integrations.commonroad_hosts import simulator_episodes
    from safelane.planners.adversarial import Oscillating, RecklessMerge
    from safelane.sim import SimConfig, paper_scenarios

    sizes = dict(zip(("expert", "shielded", "reckless", "oscillating"), np.diff(np.round(np.linspace(
        0, n, 5)).astype(int)), strict=True))  # fmt: skip
    rng = np.random.default_rng(seed)
    cells = [(nl, a) for nl in (1, 3, 5) for a in (4.0, 6.0, 8.0)]
    per = np.diff(np.round(np.linspace(0, sizes["expert"], len(cells) + 1)).astype(int))
    parts, first = [], 0
    for (nl, a), m in zip(cells, per, strict=True):
        if m:
            parts.append(paper_scenarios("CV_all", nl, a, int(m), rng, first_id=first))
            first += int(m)
    runs = []
    if parts:  # the cells' vehicle axes differ: one simulation per cell
        episodes = []
        for part in parts:
            episodes += simulator_episodes(part, seed=seed)[0]
        runs.append(("simulator, shielded, expert", episodes))

    def merges(m, shielded):
        batch = paper_scenarios("CV_all", 3, 6.0, m, rng, first_id=10_000 if shielded else 20_000)
        nominal = RecklessMerge(a_x=rng.uniform(-4.0, 3.0, m), lateral_gain=rng.uniform(0.2, 1.0, m))
        cfg = SimConfig(supervised=shielded, own_lane=True)
        return simulator_episodes(batch, seed=seed, config=cfg, nominal=nominal)[0]

    if sizes["shielded"]:
        runs.append(("simulator, shielded, reckless merges, L0", merges(int(sizes["shielded"]), True)))
    if sizes["reckless"]:
        runs.append(("simulator, unshielded, reckless merges, L0", merges(int(sizes["reckless"]), False)))
    if sizes["oscillating"]:
        m = int(sizes["oscillating"])
        batch = paper_scenarios("CV_all", 3, 6.0, m, rng, first_id=30_000)
        runs.append(("simulator, unshielded, oscillating", simulator_episodes(
            batch, seed=seed, config=SimConfig(supervised=False), nominal=Oscillating())[0]))  # fmt: skip
    return runs


def reckless_highway(env):
    """Full authority toward the target lane (benchmarks/highway_campaign.py's policy)."""
    prm, ego = env.params, env.ego
    y, vy = (float(z) for z in env.frame.y(ego.position[1], ego.lateral_speed))
    return np.array([prm.a_x_a, np.clip(2.0 * (prm.lane_width - y) - 2.5 * vy, -prm.a_y_m, prm.a_y_m)])


def highway_runs(n: int, seed: int):
    import gymnasium as gym

    from safelane.integrations.commonroad_hosts import highway_episode
    from safelane.integrations.highway import SCENE_ENV_ID, SafeLaneShield

    runs = []
    for shield, m in ((False, n - int(0.3 * n)), (True, int(0.3 * n))):
        episodes = []
        for own in (None, "brake"):
            config = {"observation": {"type": "LidarObservation"}, "decel": [4.0, 6.0, 8.0], "own_leader": own}
            env = SafeLaneShield(gym.make(SCENE_ENV_ID, config=config), shield=shield)
            count = m // 2 if own is None else m - m // 2
            base = seed * 100_000 + (50_000 if own else 0)
            episodes += [highway_episode(env, reckless_highway, base + i) for i in range(count)]
            env.close()
        runs.append((f"highway-env, {'shielded' if shield else 'unshielded'}, scene, reckless", episodes))
    return runs


def sumo_runs(n: int, seed: int):
    from safelane import Params
    from safelane.integrations.commonroad_hosts import recording_world_class, sumo_episodes
    from safelane.integrations.sumo import SumoRunner, reckless, sumo_scenarios

    prm = Params()
    world = recording_world_class()(prm)
    runs = []
    try:
        runner = SumoRunner(prm, policy=reckless, world=world)
        half = n // 2
        for shielded, m in ((False, half), (True, n - half)):
            scenarios = []
            for j, nl in enumerate((1, 3)):
                k = m // 2 if j == 0 else m - m // 2
                scenarios += sumo_scenarios(nl, 6.0, k, seed=seed + j, own_share=0.3, first_id=1000 * j)
            runs.append((f"SUMO, {'shielded' if shielded else 'unshielded'}, reckless",
                         sumo_episodes(runner, scenarios, shielded=shielded)))  # fmt: skip
    finally:
        world.close()
    return runs


def referee_all(runs, out: Path, timings):
    from safelane.integrations.commonroad import read_commonroad, to_commonroad, write_commonroad
    from safelane.integrations.commonroad_referee import compare, drivability_collisions

    rows, notes, same, sizes = [], [], 0, []
    for label, episodes in runs:
        count = collections.Counter()
        for ep in episodes:
            t0 = time.perf_counter()
            scenario, problems = to_commonroad(ep)
            t1 = time.perf_counter()
            path = write_commonroad(out / f"{ep.host}-{'S' if ep.shielded else 'U'}-{ep.episode_id}.xml",
                                    scenario=scenario, planning_problems=problems)  # fmt: skip
            t2 = time.perf_counter()
            from_file, _ = read_commonroad(path)
            t3 = time.perf_counter()
            verdict = drivability_collisions(from_file)
            agreement = compare(ep, verdict)
            t4 = time.perf_counter()
            same += drivability_collisions(scenario) == verdict
            for stage, dt in zip(("export", "write", "read", "referee"), (t1 - t0, t2 - t1, t3 - t2, t4 - t3),
                                 strict=True):  # fmt: skip
                timings[stage] += dt
            sizes.append(path.stat().st_size)
            count["episodes"] += 1
            count["host"] += ep.collided
            count["checker"] += verdict.collision
            count[agreement.kind if agreement.agree else "disagree"] += 1
            if agreement.reason:
                notes.append((label, ep.episode_id, agreement))
        rows.append((label, count))
    return rows, notes, same, sizes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--simulator", type=int, default=800, help="episodes of the built-in simulator")
    ap.add_argument("--highway", type=int, default=100, help="episodes of highway-env")
    ap.add_argument("--sumo", type=int, default=120, help="episodes of SUMO")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="keep the XML files here (default: a temporary folder)")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="safelane-commonroad-"))
    out.mkdir(parents=True, exist_ok=True)
    timings = collections.Counter()
    runs = []
    for host, make, n in (("simulator", simulator_runs, args.simulator), ("highway-env", highway_runs, args.highway),
                          ("SUMO", sumo_runs, args.sumo)):  # fmt: skip
        if n:
            t0 = time.perf_counter()
            made = make(n, args.seed)
            timings[f"run {host}"] += time.perf_counter() - t0
            runs += made
    try:
        rows, notes, same, sizes = referee_all(runs, out, timings)
    finally:
        if args.out is None:
            shutil.rmtree(out, ignore_errors=True)
    total = collections.Counter()
    print("| run | episodes | host: ego collided | checker: ego collided | both collide | both clear | disagree |")
    print("|---|---|---|---|---|---|---|")
    for label, c in rows:
        total.update(c)
        print(f"| {label} | {c['episodes']} | {c['host']} | {c['checker']} | {c['both collide']} | "
              f"{c['both clear']} | {c['disagree']} |")  # fmt: skip
    print(f"| **all** | **{total['episodes']}** | {total['host']} | {total['checker']} | {total['both collide']} | "
          f"{total['both clear']} | **{total['disagree']}** |")  # fmt: skip
    agree = total["both collide"] + total["both clear"]
    print(f"\nagreement: {agree} of {total['episodes']} episodes; verdict from the file = verdict in memory: "
          f"{same} of {total['episodes']}")  # fmt: skip
    between = [n for n in notes if n[2].agree]
    print(f"\nagreements found by the closer look (the checker on the period interpolated at 0.001 s): "
          f"{len(between)}")  # fmt: skip
    for label, eid, a in between:
        print(f"  {label} #{eid}: host step {a.host_step}, checker's first sampled step {a.checker_step}: {a.reason}")
    disagreements = [n for n in notes if not n[2].agree]
    print(f"\ndisagreements: {len(disagreements)}")
    for label, eid, a in disagreements:
        print(f"  {label} #{eid}: {a.kind}, host step {a.host_step}, checker step {a.checker_step}: {a.reason}")
    n = max(total["episodes"], 1)
    print(f"\nfiles: {n} XML files, {np.mean(sizes) / 1024:.0f} KiB on average")
    print("timings (s):", ", ".join(f"{k} {v:.1f}" for k, v in timings.items() if k.startswith("run")))
    print("per episode (ms):", ", ".join(f"{k} {1000 * timings[k] / n:.1f}" for k in ("export", "write", "read",
                                                                                      "referee")))  # fmt: skip


if __name__ == "__main__":
    main()
