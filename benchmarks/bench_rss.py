"""RSS pair checks per second: the NumPy version (safelane.baselines.rss) against ad-rss itself, in one run.

A pair check: the ego against one other vehicle — the longitudinal and the lateral safe distance and ad-rss's
verdicts. Three ad-rss figures, from the cheapest to the whole pipeline:

* closed forms — ``calculateSafeLongitudinalDistanceSameDirection`` + ``calculateSafeLateralDistance`` + the two
  comparisons, through the Python bindings, with every input object built beforehand (ad-rss's floor from Python);
* closed forms, objects built per pair — what :func:`safelane.baselines.rss_adrss.pair_check` does;
* full check — ``RssCheck.calculateProperResponse`` on a prebuilt one-lane world model with one object (situation
  extraction, checking, response resolution), the pipeline an AV runs.

    .venv/bin/python benchmarks/bench_rss.py [--pairs 100000] [--adrss-pairs 3000]

Needs the extra ``rss`` for the ad-rss figures (prints the NumPy ones alone otherwise). Figures swing with the
machine's load; the ratio is taken within one run.
"""

from __future__ import annotations

import argparse
import platform
import time
import warnings

import numpy as np

from safelane import Params
from safelane.baselines import rss_adrss
from safelane.baselines.rss import RssParams, pair_check


def situations(n: int, seed: int = 0):
    """Random ego/other pairs: other in the target lane or the ego's, ahead or behind, speeds 0–40 m/s."""
    rng = np.random.default_rng(seed)
    ex, ey = np.zeros(n), rng.uniform(0.0, 3.5, n)
    evx, evy = rng.uniform(0.0, 40.0, n), rng.uniform(-1.5, 1.5, n)
    x, y = rng.uniform(-150.0, 150.0, n), rng.choice([0.0, 3.5], n)
    vx, vy = rng.uniform(0.0, 40.0, n), np.zeros(n)
    return ex, ey, evx, evy, x, y, vx, vy


def best_rate(fn, count: int, repeats: int = 5) -> float:
    """The best of ``repeats`` timings, as items per second."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return count / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=100_000, help="batch size of the NumPy check")
    ap.add_argument("--adrss-pairs", type=int, default=3000, help="pairs timed through ad-rss (one call each)")
    args = ap.parse_args()
    prm, rss = Params(), RssParams()
    print(f"RSS pair checks/s ({platform.processor() or platform.machine()}, Python {platform.python_version()}; "
          f"ad-rss's default parameters)")  # fmt: skip

    big = situations(args.pairs)
    numpy_rate = best_rate(lambda: pair_check(*big, rss, prm), args.pairs)
    small = situations(1000, seed=1)
    numpy_small = best_rate(lambda: pair_check(*small, rss, prm), 1000)
    one = [float(a[0]) for a in small]
    numpy_scalar = best_rate(lambda: [pair_check(*one, rss, prm) for _ in range(200)], 200)
    print(f"  NumPy, batch {args.pairs:>7,}:                 {numpy_rate:14,.0f} pairs/s")
    print(f"  NumPy, batch   1,000:                 {numpy_small:14,.0f} pairs/s")
    print(f"  NumPy, one pair per call:             {numpy_scalar:14,.0f} pairs/s")
    if not rss_adrss.available():
        print(f"  ad-rss: not installed ({rss_adrss.INSTALL_HINT})")
        return

    m = args.adrss_pairs
    sub = [a[:m] for a in situations(m, seed=2)]
    _, phys, _, _, structured = rss_adrss._modules()
    ego_dyn = rss_adrss.dynamics(rss, rss.response_time_ego)
    other_dyn = rss_adrss.dynamics(rss, rss.response_time_other)
    pairs = []
    for i in range(m):
        ego = rss_adrss.object_state(ego_dyn, sub[2][i], -sub[3][i], prm.vehicle_length, prm.vehicle_width)
        other = rss_adrss.object_state(other_dyn, sub[6][i], -sub[7][i], prm.vehicle_length, prm.vehicle_width)
        front, rear = (other, ego) if sub[4][i] > 0 else (ego, other)
        left, right = (other, ego) if sub[5][i] > sub[1][i] else (ego, other)
        lon = phys.Distance(max(abs(sub[4][i]) - prm.vehicle_length, 0.0))
        lat = phys.Distance(max(abs(sub[5][i] - sub[1][i]) - prm.vehicle_width, 0.0))
        pairs.append((front, rear, left, right, lon, lat))

    def closed_forms():
        d_lon, d_lat = phys.Distance(0.0), phys.Distance(0.0)
        for front, rear, left, right, lon, lat in pairs:
            structured.calculateSafeLongitudinalDistanceSameDirection(front, rear, d_lon)
            structured.calculateSafeLateralDistance(left, right, d_lat)
            _ = (lon > d_lon) or (lat > d_lat)

    def wrapper():
        for i in range(m):
            rss_adrss.pair_check(*(float(a[i]) for a in sub), rss, prm)

    adrss_closed = best_rate(closed_forms, m, repeats=3)
    adrss_wrapper = best_rate(wrapper, m, repeats=1)

    import ad_rss

    checker = ad_rss.rss.core.RssCheck()
    gaps = np.abs(sub[4]) - prm.vehicle_length
    worlds = [rss_adrss.same_lane_world(float(sub[2][i]), float(sub[6][i]), float(gaps[i]), rss, prm, object_id=i + 1,
                                        time_index=i + 1) for i in range(m)]  # fmt: skip

    def full():
        for model in worlds:
            rss_adrss.full_check(checker, model)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        adrss_full = best_rate(full, m, repeats=1)
    print(f"  ad-rss closed forms (objects prebuilt): {adrss_closed:12,.0f} pairs/s")
    print(f"  ad-rss closed forms (objects per pair): {adrss_wrapper:12,.0f} pairs/s")
    print(f"  ad-rss full check (RssCheck, prebuilt world): {adrss_full:6,.0f} pairs/s "
          f"({1e6 / adrss_full:.0f} µs per pair)")  # fmt: skip
    print(f"ratio NumPy (batch {args.pairs:,}) / ad-rss closed forms: {numpy_rate / adrss_closed:,.0f}x; "
          f"/ ad-rss full check: {numpy_rate / adrss_full:,.0f}x")  # fmt: skip


if __name__ == "__main__":
    main()
