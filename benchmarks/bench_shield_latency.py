"""Latency of the shield for one vehicle (``Shield.step`` at batch 1), beside the same shield per row at batch
1,000 and ad-rss's full check per object pair (``RssCheck.calculateProperResponse`` on a prebuilt one-lane world),
all measured in one run. The issue's target for one vehicle: ≤ 100 µs (ad-rss: about 133 µs per object pair).

    .venv/bin/python benchmarks/bench_shield_latency.py [--calls 2000] [--adrss-pairs 2000]

The baseline beside it: the same period through the NumPy stages (``shield.core.step``), same run.
Each figure is the best of 5 timings of a loop of calls (the median of the per-call times is printed too). Also
prints where a batch-1 step spends its time, by stage (``safelane.shield.stages``), from cProfile. Figures swing
with the machine's load; compare within one run.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import os
import platform
import pstats
import sys
import time
import warnings

import numpy as np

from safelane import Params
from safelane.shield import Shield, Situation, core, validation


def situation(b: int) -> Situation:
    """``b`` copies of one mid-manoeuvre situation (a connected chain of 3, a collaborative connected F)."""
    return Situation.from_arrays(
        t=0.0, ego=(np.zeros(b), np.full(b, 1.2), np.full(b, 30.0), np.full(b, 0.5)), follower=(np.full(b, -20.0),
        np.full(b, 30.0)), leaders=(np.tile([20.0, 40.0, 60.0], (b, 1)), np.full((b, 3), 30.0)), n_connected=2,
        f_connected=True, f_collaborative=True,
    )  # fmt: skip


@contextlib.contextmanager
def _quiet_stdout():
    """File descriptor 1 to /dev/null for a while (ad-rss's C++ logger writes there, past Python's sys.stdout)."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            os.dup2(saved, 1)
            os.close(saved)


def per_call(fn, calls: int, repeats: int = 5) -> tuple[float, float]:
    """``(best, median)`` seconds per call over ``repeats`` loops of ``calls`` calls."""
    loops = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        loops.append((time.perf_counter() - t0) / calls)
    return min(loops), float(np.median(loops))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=2000, help="Shield.step calls per timing loop")
    ap.add_argument("--adrss-pairs", type=int, default=2000, help="ad-rss full checks per timing loop")
    args = ap.parse_args()
    prm = Params()
    print(f"bench_shield_latency: {platform.machine()}, Python {platform.python_version()}, NumPy {np.__version__}")

    one, many = situation(1), situation(1000)
    proposal1 = (np.array([1.0]), np.array([0.8]))
    proposal_many = (np.full(1000, 1.0), np.full(1000, 0.8))
    shield1, shield_many = Shield(prm, variant="CV_all"), Shield(prm, variant="CV_all")
    shield1.reset(one)
    shield_many.reset(many)
    for _ in range(20):  # warm up (and compile or load the kernels)
        shield1.step(one, proposal1)
        shield_many.step(many, proposal_many)
    best1, med1 = per_call(lambda: shield1.step(one, proposal1), args.calls)
    best_b, med_b = per_call(lambda: shield_many.step(many, proposal_many), max(args.calls // 50, 5))
    print(f"  Shield.step, one vehicle ({shield1.last_path}): {best1 * 1e6:9.1f} µs per call (median of loops "
          f"{med1 * 1e6:.1f})   target <= 100 µs: {'pass' if best1 <= 100e-6 else 'MISS'}")  # fmt: skip
    print(f"  Shield.step, batch 1,000, per row:    {best_b / 1000 * 1e6:9.2f} µs (median {med_b / 1000 * 1e6:.2f}); "
          f"one call {best_b * 1e3:.2f} ms")  # fmt: skip
    # The baseline: the same period through the NumPy stages (shield.core.step, the functional API; with the
    # Shield's own input checks, so both figures include them).
    staged = {"state": core.init(one, prm, shield1.config, "CV_all")}

    def stages_step():
        validation.situation_arg(one, "Shield.step").validate(prm)
        staged["state"], _ = core.step(staged["state"], one, proposal1, prm, shield1.config, "CV_all")

    best_s, med_s = per_call(stages_step, max(args.calls // 4, 50))
    print(f"  the same period, NumPy stages:        {best_s * 1e6:9.1f} µs per call (median of loops {med_s * 1e6:.1f})"
          f"   (baseline, same run; {best_s / best1:.1f}x the compiled period)")  # fmt: skip

    from safelane.baselines import rss_adrss

    if not rss_adrss.available():
        print(f"  ad-rss: not installed ({rss_adrss.INSTALL_HINT}); no baseline in this run")
    else:
        import ad_rss

        from safelane.baselines.rss import RssParams

        rss = RssParams()
        checker = ad_rss.rss.core.RssCheck()
        rng = np.random.default_rng(0)
        m = args.adrss_pairs
        worlds = [rss_adrss.same_lane_world(float(rng.uniform(10, 40)), float(rng.uniform(10, 40)),
                                            float(rng.uniform(5, 80)), rss, prm, object_id=i + 1, time_index=i + 1)
                  for i in range(m)]  # fmt: skip

        def full():
            for model in worlds:
                rss_adrss.full_check(checker, model)

        with warnings.catch_warnings(), _quiet_stdout():  # ad-rss logs every dangerous state to stdout
            warnings.simplefilter("ignore")
            best = per_call(full, 1, repeats=1)[0] / m  # once: ad-rss requires rising time indices
        print(f"  ad-rss full check, one object pair:   {best * 1e6:9.1f} µs   (baseline, same run)")
        print(f"ratio Shield.step (one vehicle) / ad-rss full check (one pair): {best1 / best:.1f}x")

    profile = cProfile.Profile()
    profile.enable()
    for _ in range(300):
        stages_step()
    profile.disable()
    stats = pstats.Stats(profile)
    total = max(row[3] for key, row in stats.stats.items() if key[2] == "stages_step")
    print("where one batch-1 period goes through the NumPy stages (cProfile, cumulative per stage, share of the whole "
          "call with its input checks; profiling inflates every figure):")  # fmt: skip
    for key, row in sorted(stats.stats.items(), key=lambda kv: -kv[1][3]):
        if key[0].endswith("stages.py") and key[2] in ("observe", "worst_case", "proposal", "frame", "decide",
                                                       "command", "remember"):  # fmt: skip
            print(f"  {key[2]:<11} {row[3] / 300 * 1e6:8.1f} µs  ({row[3] / total:5.1%})")


if __name__ == "__main__":
    main()
