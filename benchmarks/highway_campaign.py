"""The shield in highway-env: a reckless nominal policy with and without the shield, crashes by
highway-env's own ``crashed`` flag.

Cases: the lane-change scene (``safelane/HighwayScene-v0``: F, a platoon L1..LN of highway-env's IDM vehicles, L(N+1)
braking suddenly at a ∈ {4, 6, 8} m/s²); the scene with an own-lane leader L0 that brakes as well (the shield with
its own-lane check and, as an ablation, without it: ``ShieldConfig(own_lane=False)``, the shield before issue 17);
random ``highway-v0`` traffic (20 vehicles, 10 s episodes, the ego merging into the lane on its left, or right from
lane 0) on highway-env's default four lanes — where MOBIL may move a vehicle into the target lane ahead of the ego
from the lane beyond it, outside the shield's assumptions — and inside them: two lanes (the paper's) and traffic
that, until the ego lies wholly in the target lane, starts no lane change into the ego's target or original lane
beside the ego or between it and its nearest leader there (``NoCutInIDMVehicle``; every other MOBIL decision is
highway-env's). The policy: full authority — ``a_x = a_x_a`` and the lateral acceleration saturated toward the
target-lane centre (``a_y = clip(2 (w − y) − 2.5 v_y, ±a_y_m)``). Every crash is classified (partner, its lane, the
ego's phase, who ran into whom), and every episode records whether the traffic broke the shield's assumptions by
itself (another vehicle crashed — highway-env then brakes it at ``speed`` m/s², beyond ``a_x_d`` — or reversed)
and whether a vehicle cut in (``info["cut_in"]``).

The shield passes every vehicle besides F, the chain and L0 to the shield as the Situation's ``others`` (the world
model, docs/safety.md "Other vehicles' lane changes"); mode ``shield, paper world`` does not (the wrapper before the
world model). ``highway-v0 stock`` is highway-env's default ``highway-v0`` (4 lanes, 50 vehicles, 40 s, MOBIL
``IDMVehicle`` traffic) changed only where the wrapper must — ``ContinuousAction`` at 10 Hz simulation and policy
(``HIGHWAY_CONFIG``) — and in the observation (``LidarObservation``, below; it changes no trajectory). Each crash is
judged by ``info["crash_blame"]`` (RSS's blame rule): the "ego-responsible" column counts ``"ego"`` and ``"both"``.
Mode ``RSS_matched``: the wrapper with the RSS baseline's decision rule (variant ``RSS_matched``) instead of the
paper's, on the same seeds and the same world model.

    .venv/bin/python benchmarks/highway_campaign.py --case "highway-v0 stock" --workers 1 --modes shield

    .venv/bin/python benchmarks/highway_campaign.py                      # the full campaign (2 workers)
    .venv/bin/python benchmarks/highway_campaign.py --episodes 10 --workers 1   # a quick look
    .venv/bin/python benchmarks/highway_campaign.py --case "highway-v0, 2 lanes, no cut-ins"   # one case

Observation type: LidarObservation (the policy reads the road, not the observation; highway-env's default
Kinematics observation costs about half of a step with pandas).
"""

from __future__ import annotations

import argparse
import collections
import json
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

OBS = {"type": "LidarObservation"}


def make_env(case: dict, shield: bool, own_lane: bool = True, others: bool = True, variant: str | None = None):
    import gymnasium as gym

    from safelane.integrations.highway import HIGHWAY_CONFIG, NO_CUT_IN_CONFIG, SCENE_ENV_ID, SafeLaneShield
    from safelane.shield import ShieldConfig

    if case["env"] == "scene":
        config = {"observation": OBS, "decel": case["decel"], "own_leader": case.get("own_leader")}
        env = gym.make(SCENE_ENV_ID, config=config)
    else:
        config = {**HIGHWAY_CONFIG, "observation": OBS}
        if not case.get("stock"):
            config.update(vehicles_count=20, duration=10)
        if case.get("lanes"):
            config["lanes_count"] = case["lanes"]
        if not case.get("cut_ins", True):
            config.update(NO_CUT_IN_CONFIG)
        env = gym.make("highway-v0", config=config)
    return SafeLaneShield(env, shield=shield, config=ShieldConfig(own_lane=own_lane), others=others,
                          variant=variant)  # fmt: skip


def reckless(env, a_x: float) -> np.ndarray:
    """Full authority toward the target lane (shield frame: a_y > 0 toward it)."""
    prm, ego = env.params, env.ego
    y, vy = (float(z) for z in env.frame.y(ego.position[1], ego.lateral_speed))
    return np.array([a_x, np.clip(2.0 * (prm.lane_width - y) - 2.5 * vy, -prm.a_y_m, prm.a_y_m)])


def run_chunk(job):
    case, mode, seeds, a_x, records_path = job
    env = make_env(case, shield=mode != "off", own_lane=mode != "shield, no own-lane check",
                   others=mode != "shield, paper world", variant=MODE_VARIANTS.get(mode))  # fmt: skip
    records, steps, t0 = [], 0, time.perf_counter()
    for seed in seeds:
        env.reset(seed=int(seed))
        road = env.unwrapped.road
        done, interventions, others_crashed, reversed_ = False, 0, False, False
        ax = env.params.a_x_a if a_x is None else a_x
        while not done:
            _, _, terminated, truncated, info = env.step(reckless(env, ax))
            steps += 1
            interventions += info["intervened"]
            if not info["crashed"]:  # crashes among the others before the ego's (its partner is marked too)
                others_crashed |= any(v.crashed for v in road.vehicles if v is not env.ego)
            reversed_ |= any(v.speed < -1e-9 for v in road.vehicles)
            done = terminated or truncated
        records.append({
            "seed": int(seed), "crashed": bool(info["crashed"]), "crash": info.get("crash"),
            "success": bool(info["completed"] and not info["crashed"]), "interventions": interventions,
            "steps": env.unwrapped.steps, "others_crashed": others_crashed, "reversed": reversed_,
            "cut_in": bool(info["cut_in"]), "crash_blame": info["crash_blame"],
        })  # fmt: skip
        if records_path:
            with open(records_path, "a") as f:
                f.write(json.dumps({"case": case_name(case), "mode": mode, **records[-1]}) + "\n")
    return records, steps, time.perf_counter() - t0


CASES = {
    "scene a=4": {"env": "scene", "decel": [4.0]},
    "scene a=6": {"env": "scene", "decel": [6.0]},
    "scene a=8": {"env": "scene", "decel": [8.0]},
    "scene a∈{4,6,8} + braking L0": {"env": "scene", "decel": [4.0, 6.0, 8.0], "own_leader": "brake"},
    "highway-v0": {"env": "highway"},
    "highway-v0, 2 lanes, no cut-ins": {"env": "highway", "lanes": 2, "cut_ins": False},
    "highway-v0 stock": {"env": "highway", "stock": True},
}
MODES = ("shield", "off", "shield, no own-lane check", "shield, paper world", "RSS_matched")
#: Modes run by a different variant of the wrapper's shield.
MODE_VARIANTS = {"RSS_matched": "RSS_matched"}


def case_name(case: dict) -> str:
    return next(name for name, c in CASES.items() if c is case or c == case)


def default_modes(case: dict) -> list[str]:
    return ["shield", "off"] + (["shield, no own-lane check"] if case.get("own_leader") else [])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=70, help="episodes per scene case (x3 for highway-v0)")
    parser.add_argument("--highway-episodes", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--ax", type=float, default=None, help="the policy's a_x (default a_x_a)")
    parser.add_argument("--case", action="append", choices=list(CASES), help="run only this case (repeatable)")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=None,
                        help="these modes in every case (default: shield, off and the own-lane ablation)")  # fmt: skip
    parser.add_argument("--records", default=None, help="append one JSON line per episode to this file")
    args = parser.parse_args()

    jobs, keys = [], []
    for name, case in CASES.items():
        if args.case and name not in args.case:
            continue
        n = args.highway_episodes if case["env"] == "highway" else args.episodes
        modes = args.modes or default_modes(case)
        seeds = np.arange(args.seed, args.seed + n)
        for mode in modes:
            for chunk in np.array_split(seeds, max(args.workers, 1)):
                if chunk.size:
                    jobs.append((case, mode, chunk.tolist(), args.ax, args.records))
                    keys.append((name, mode))
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run_chunk, jobs))
    merged = collections.defaultdict(lambda: [[], 0, 0.0])
    for key, (records, steps, secs) in zip(keys, results, strict=True):
        merged[key][0].extend(records)
        merged[key][1] += steps
        merged[key][2] += secs

    wall, ax = time.perf_counter() - t0, "a_x_a" if args.ax is None else args.ax
    print(f"highway-env campaign: reckless policy (a_x = {ax}, full lateral authority), seeds from {args.seed}, "
          f"{wall:.0f} s wall, {args.workers} workers\n")  # fmt: skip
    print("| case | shield | episodes | crashes (highway-env) | ego-responsible (blame) | success | "
          "interventions/step | other vehicles crashed | a vehicle reversed | steps/s (per process) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for (name, mode), (records, steps, secs) in merged.items():
        n = len(records)
        crashes = sum(r["crashed"] for r in records)
        ego_resp = sum(r["crash_blame"] in ("ego", "both") for r in records)
        success = sum(r["success"] for r in records)
        inter = sum(r["interventions"] for r in records) / max(steps, 1)
        others = sum(r["others_crashed"] for r in records)
        rev = sum(r["reversed"] for r in records)
        print(f"| {name} | {mode} | {n} | {crashes} | {ego_resp} | {success / n:.3f} | {inter:.3f} | {others} | "
              f"{rev} | {steps / secs:.0f} |")  # fmt: skip
    print("\nCrashes by class (partner, its lane, the ego's phase, who ran into whom):")
    for (name, mode), (records, _, _) in merged.items():
        classes = collections.Counter(
            (r["crash"]["partner"], r["crash"]["lane"], r["crash"]["ego_phase"], r["crash"]["kind"],
             "partner changing lanes" if r["crash"].get("partner_changing_lanes") else "",
             "traffic broke assumptions" if r["others_crashed"] or r["reversed"] else "",
             f"blame {r['crash_blame']}")
            for r in records if r["crashed"]
        )  # fmt: skip
        for cls, count in classes.most_common():
            print(f"  {name} | {mode}: {count} x {' / '.join(c for c in cls if c)}")
        if mode != "off":
            seeds = [r["seed"] for r in records if r["crashed"]]
            if seeds:
                print(f"  {name} | {mode}: crashed seeds {seeds[:20]}")
    print(
        "\nEpisodes with a cut-in (info['cut_in']: before the ego lay wholly in the target lane, a vehicle began "
        "moving into the target or the ego's lane beside the ego or between it and its nearest leader there):"
    )
    for (name, mode), (records, _, _) in merged.items():
        if CASES[name]["env"] == "highway":
            cut = [r for r in records if r["cut_in"]]
            print(f"  {name} | {mode}: {len(cut)} of {len(records)}, crashed {sum(r['crashed'] for r in cut)}")


if __name__ == "__main__":
    main()
