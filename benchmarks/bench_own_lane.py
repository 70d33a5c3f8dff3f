"""The shield's candidate check with an own-lane leader ``L0``, uncompiled and compiled, in the same run.

``decide._with_own`` checks the rows with ``L0`` through the period at the candidate (``candidate_period``), ``L0``
over it (``own_lane.own_period``) and the own-lane evasion check (``own_lane.own_lane_core``: closed forms against
``xp`` with a ``SEARCH_STEPS`` bisection). The NumPy path evaluates them on arrays (``SAFELANE_NO_NUMBA=1``: what
mutation testing and a machine without numba run); ``shield/_fast_own.py`` compiles the same functions and calls them
once per row. This script times both on the same random states — one large batch, and one row per call (the shield
of one vehicle, as SUMO runs it) — checks that they agree bit for bit, and does the same for ``own_lane_core``
alone and, where ``decide`` dispatches to the kernel (``decide.own_kernel``), for the whole ``check_candidate``.

Run with ``python benchmarks/bench_own_lane.py [--n 20000] [--calls 300] [--repeat 3]``. It prints; it asserts
nothing but the bit-for-bit agreement (timings depend on what else runs on the machine).
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from bench_one_source import best_of
from safelane import Params
from safelane.safety._backend import ARRAY, FEASIBILITY_TOL_M
from safelane.safety.evasion import fast_kernel
from safelane.safety.lateral import LATERAL_TOL_M
from safelane.safety.own_lane import own_lane_core, own_period
from safelane.shield import decide

ORDER = ("ego_x", "ego_y", "ego_vx", "ego_vy", "a_x", "a_y", "l1_x", "l1_v", "l1_decel", "f_x", "f_v", "f_aggressive")


def random_states(rng, n: int, prm: Params) -> tuple[dict, tuple]:
    """Candidate-check states with ``L0`` in every row: the ego on both sides of ``y_safe`` and of the lane boundary,
    gaps to L1 and F a few centimetres around ``p_m`` for half of the rows, any candidate; L0 close ahead at about the
    ego's speed braking up to ``a_x_d`` (half), at rest (a sixth), far away (a sixth), or exactly at ``p_m`` at the
    ego's speed braking at ``a_x_d`` (a sixth)."""
    u = rng.uniform
    ego_x, ego_vx = u(-50.0, 50.0, n), u(2.0, 30.0, n)
    near = lambda: np.where(u(0, 1, n) < 0.5, u(-0.03, 0.06, n), u(0.0, 40.0, n))  # noqa: E731
    s = dict(
        ego_x=ego_x, ego_y=u(-0.3, 2.2, n), ego_vx=ego_vx, ego_vy=u(-1.2, 1.2, n), a_x=u(-prm.a_x_d, prm.a_x_a, n),
        a_y=u(-prm.a_y_m, prm.a_y_m, n), l1_x=ego_x + prm.p_m + near(), l1_v=np.maximum(ego_vx + u(-2.0, 2.0, n), 0.0),
        l1_decel=np.where(u(0, 1, n) < 0.2, prm.a_x_d, u(0.0, prm.a_x_d, n)), f_x=ego_x - prm.p_m - near(),
        f_v=np.maximum(ego_vx + u(-2.0, 2.0, n), 0.0), f_aggressive=u(0, 1, n) < 0.5,
    )  # fmt: skip
    kind = rng.integers(0, 6, n)
    slack = np.where(u(0, 1, n) < 0.5, np.exp(u(np.log(1e-2), np.log(60.0), n)), u(-1.0, 20.0, n))
    l0_x = np.select([kind == 3, kind == 4, kind == 5], [ego_x + prm.p_m + u(0.0, 60.0, n), ego_x + u(200, 2000, n),
                                                          ego_x + prm.p_m], ego_x + prm.p_m + slack)  # fmt: skip
    l0_v = np.select([kind == 3, kind == 5], [0.0, ego_vx], np.maximum(ego_vx + rng.normal(0.0, 3.0, n), 0.0))
    l0_decel = np.where((kind == 5) | (u(0, 1, n) < 1 / 3), prm.a_x_d, u(0.05, prm.a_x_d, n))
    return s, (l0_x, l0_v, l0_decel)


def numpy_block(args, own, prm: Params, level: float):
    """``decide._with_own``'s NumPy block on the rows with ``L0``: what ``_fast_own.check_own`` returns."""
    ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggr = args
    o_x, o_v, o_decel = own
    with np.errstate(all="ignore"):
        state, period_ok, done = decide.candidate_period(
            ARRAY, ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggr, prm, prm.p_m, prm.dt,
            level, LATERAL_TOL_M, FEASIBILITY_TOL_M,
        )  # fmt: skip
        period_ok, done, ox, ov = own_period(ARRAY, ego_x, ego_vx, a_x, o_x, o_v, o_decel, period_ok, done, state[3],
                                             prm.p_m, prm.dt, FEASIBILITY_TOL_M)  # fmt: skip
        ex, ey, evx, evy, lx, lv, fx, fv = state
        exists, parts = own_lane_core(ex, ey, evx, evy, lx, lv, l1_decel, fx, fv, f_aggr, ox, ov, o_decel, prm.p_m,
                                      prm.p_m, decide.own_margin(prm), prm)  # fmt: skip
    return state, period_ok, done, (ox, ov), exists, parts


def _bits(a, n: int) -> np.ndarray:
    a = np.ascontiguousarray(np.broadcast_to(a, (n,)))
    return a.view(np.int64) if a.dtype == np.float64 else a


def same_bits(a, b, n: int) -> bool:
    """Every array of two nested outputs equal bit for bit (floats through their 64-bit patterns)."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same_bits(a[k], b[k], n) for k in a)
    if isinstance(a, tuple):
        return len(a) == len(b) and all(same_bits(x, y, n) for x, y in zip(a, b, strict=True))
    return bool(np.array_equal(_bits(a, n), _bits(b, n)))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20_000, help="rows of the large batch")
    ap.add_argument("--calls", type=int, default=300, help="one-row calls timed")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs (the best counts)")
    args = ap.parse_args(argv)
    if fast_kernel() is None:
        sys.exit("numba is not installed (or SAFELANE_NO_NUMBA=1): nothing compiled to compare")
    from safelane.shield import _fast_own

    prm = Params()
    s, own = random_states(np.random.default_rng(0), args.n, prm)
    cand = tuple(s[k] for k in ORDER)
    level = max(decide.own_completion_level(prm), decide.completion_level(decide.commit_guard, prm))
    core_args = (s["ego_x"], s["ego_y"], s["ego_vx"], s["ego_vy"], s["l1_x"], s["l1_v"], s["l1_decel"], s["f_x"],
                 s["f_v"], s["f_aggressive"], *own, prm.p_m, prm.p_m, decide.own_margin(prm))  # fmt: skip
    n, k = args.n, min(args.calls, args.n)

    def row(i, xs):
        return tuple(a[i : i + 1] for a in xs)

    checks = [
        ("candidate check with L0, whole batch", n,
         lambda: numpy_block(cand, own, prm, level), lambda: _fast_own.check_own(cand, own, prm, level)),
        ("candidate check with L0, one row a call", k,
         lambda: [numpy_block(row(i, cand), row(i, own), prm, level) for i in range(k)],
         lambda: [_fast_own.check_own(row(i, cand), row(i, own), prm, level) for i in range(k)]),
        ("own_lane_core alone, whole batch", n,
         lambda: own_lane_core(*core_args, prm), lambda: _fast_own.own_lane_rows(*core_args, prm)),
    ]  # fmt: skip
    # Bit for bit, on every row of the batch and on each one-row call.
    agree = same_bits(numpy_block(cand, own, prm, level), _fast_own.check_own(cand, own, prm, level), n)
    for i in range(k):
        one = (row(i, cand), row(i, own), prm, level)
        agree &= same_bits(numpy_block(*one), _fast_own.check_own(*one), 1)
    with np.errstate(all="ignore"):
        agree &= same_bits(own_lane_core(*core_args, prm), _fast_own.own_lane_rows(*core_args, prm), n)
    if not agree:
        sys.exit("the compiled rows and the NumPy path disagree: a bug")
    print(f"bench_own_lane: {n:,} random states with L0 ({k} of them one row a call), best of {args.repeat}; every "
          "output bit-identical between the two paths\n")  # fmt: skip
    print(f"{'check':<42} {'NumPy checks/s':>15} {'compiled checks/s':>18} {'speed-up':>9}")
    for name, rows, slow, fast in checks:
        with np.errstate(all="ignore"):
            a = rows / best_of(args.repeat, slow)
        b = rows / best_of(args.repeat, fast)
        print(f"{name:<42} {a:>15,.0f} {b:>18,.0f} {b / a:>8.1f}x")
    if hasattr(decide, "own_kernel"):  # the whole check_candidate (with verdict_of's plans), dispatched
        times = {}
        for label, env in (("NumPy", "1"), ("compiled", "0")):
            os.environ["SAFELANE_NO_NUMBA"] = env
            times[label] = best_of(args.repeat, lambda: [decide.check_candidate(*row(i, cand), prm, own=row(i, own))
                                                         for i in range(k)])  # fmt: skip
        os.environ.pop("SAFELANE_NO_NUMBA")
        print(f"{'check_candidate with L0, one row a call':<42} {k / times['NumPy']:>15,.0f} "
              f"{k / times['compiled']:>18,.0f} {times['NumPy'] / times['compiled']:>8.1f}x")  # fmt: skip
    else:
        print("(decide.check_candidate does not dispatch the rows with L0 to the kernel yet: not timed)")
    print(f"\nload average at the end: {' '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
