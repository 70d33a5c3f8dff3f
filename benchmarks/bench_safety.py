"""Throughput of the safety engine: full ``evasion_exists`` checks per second, and scalar latency.

Run with ``python benchmarks/bench_safety.py [--quick]``. The script prints figures next to their targets and a
pass/miss word; it asserts nothing (timings depend on the machine and on what else runs on it).

States are random but realistic: speeds 20–35 m/s, gaps 10–40 m to ``L1`` and the follower, ``p_y`` in
``[0, 3.5]`` m, ``v_y`` in ``[-1, 1]`` m/s, ``L1``'s worst-case deceleration in ``[0, a_x_d]`` and a 50/50
mix of aggressive and collaborative followers.
"""

from __future__ import annotations

import argparse
import statistics
import time
import timeit

import numpy as np

from safelane import Params
from safelane.safety import evasion_exists, plan_evasion, worst_case_leader_decel

TARGET_CHECKS_PER_S = 2e6  # at batch 1e6
TARGET_SCALAR_US = 50.0


def random_states(rng: np.random.Generator, n: int, params: Params) -> dict[str, np.ndarray]:
    """``n`` realistic ego/``L1``/follower states as keyword arguments of :func:`evasion_exists`."""
    return dict(
        ego_px=np.zeros(n),
        ego_py=rng.uniform(0.0, 3.5, n),
        ego_vx=rng.uniform(20.0, 35.0, n),
        ego_vy=rng.uniform(-1.0, 1.0, n),
        l1_p=rng.uniform(10.0, 40.0, n),
        l1_v=rng.uniform(20.0, 35.0, n),
        l1_decel=rng.uniform(0.0, params.a_x_d, n),
        f_p=-rng.uniform(10.0, 40.0, n),
        f_v=rng.uniform(20.0, 35.0, n),
        follower_aggressive=rng.random(n) < 0.5,
    )


def random_chains(rng: np.random.Generator, n: int, n_links: int, params: Params) -> dict[str, np.ndarray]:
    """``n`` leader chains ``L1..L(N+1)`` with 10–40 m gaps, as keyword arguments of the chain functions."""
    gaps = rng.uniform(10.0, 40.0, (n, n_links + 1))
    return dict(
        p=np.cumsum(gaps, axis=-1),
        v=rng.uniform(20.0, 35.0, (n, n_links + 1)),
        promise_decel=rng.uniform(0.0, 0.5 * params.a_x_d, (n, n_links)),
    )


def _seconds_per_call(fn, repeats: int, budget_s: float = 0.2) -> float:
    """Median over ``repeats`` rounds of the mean wall time of one call (after a warm-up call).

    A round repeats the call until it has run for ``budget_s``, so small batches are timed over many calls.
    """
    start = time.perf_counter()
    fn()
    number = max(1, int(budget_s / max(time.perf_counter() - start, 1e-9)))
    rounds = timeit.repeat(fn, number=number, repeat=repeats)
    return statistics.median(rounds) / number


def _verdict(ok: bool) -> str:
    return "pass" if ok else "MISS"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (a rough figure in a few seconds)")
    args = parser.parse_args()
    repeats = 3 if args.quick else 7
    params = Params()
    rng = np.random.default_rng(0)

    print("evasion_exists (full check: lateral Eq. 5, longitudinal Eqs. 6-8, follower Eq. 9)")
    for n in (1, 1_000, 1_000_000):
        states = random_states(rng, n, params)
        sec = _seconds_per_call(lambda s=states: evasion_exists(**s, params=params), repeats)
        rate = n / sec
        line = f"  batch {n:>9,}: {rate / 1e6:8.3f} M checks/s  ({sec * 1e3:9.3f} ms per call)"
        if n == 1_000_000:
            line += f"   target >= {TARGET_CHECKS_PER_S / 1e6:.0f} M/s  {_verdict(rate >= TARGET_CHECKS_PER_S)}"
        print(line)

    one = {k: v[0].item() for k, v in random_states(rng, 1, params).items()}
    number = 2_000 if args.quick else 10_000
    per_call = timeit.repeat(lambda: evasion_exists(**one, params=params), number=number, repeat=repeats)
    scalar_us = statistics.median(per_call) / number * 1e6
    print(
        f"  scalar call (Python floats): {scalar_us:8.2f} us median   "
        f"target <= {TARGET_SCALAR_US:.0f} us  {_verdict(scalar_us <= TARGET_SCALAR_US)}"
    )

    print("context (batch 100,000)")
    n = 100_000
    states = random_states(rng, n, params)
    sec = _seconds_per_call(lambda: plan_evasion(**states, params=params), repeats)
    print(f"  plan_evasion:                 {n / sec / 1e6:8.3f} M plans/s   ({sec * 1e3:8.2f} ms per call)")
    chains = random_chains(rng, n, 10, params)
    sec = _seconds_per_call(lambda: worst_case_leader_decel(**chains, params=params), repeats)
    print(f"  worst_case_leader_decel N=10: {n / sec / 1e6:8.3f} M chains/s  ({sec * 1e3:8.2f} ms per call)")


if __name__ == "__main__":
    main()
