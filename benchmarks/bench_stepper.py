"""The compiled period stepped from Python (``sim/_stepper.Stepper``), the way ``simulate_batch`` runs the neural
planner: the whole loop, before and after the Python side of the period was cut, and the share of ``step_kernel``.

Run with ``python benchmarks/bench_stepper.py [--samples 20000] [--repeats 3]``. One batch of the ``paper`` preset
(its network ``mlp_paper`` the nominal planner), N = 3, a = 5 m/s², the four variants in equal parts, runs two ways,
interleaved, best of ``--repeats`` each:

- ``before``: :meth:`Stepper.step` (value semantics: every array of the state copied every period) with the feature
  map's whole-plan ``cumsum`` (:func:`_features_before`, the code the feature map had before, kept here as the
  baseline; ``ClosedLoop.observe``'s ``l1_plan`` is today's in both ways);
- ``now``: :meth:`Stepper.advance` (the rows advanced in place, as ``simulate_batch`` steps them) with the feature
  map as it is.

Both build the same results table (checked, bit for bit, and printed). Prints the wall and CPU time of each (the
best wall time's run) and the time inside ``step_kernel`` (the compiled period itself), its share of the CPU time and
the CPU time outside it. Asserts nothing about time: timings
depend on the machine and on what else runs on it.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

from safelane.planners import features as feature_map
from safelane.planners.base import clip_actions
from safelane.planners.features import PLAN_TIMES_S, plan_steps, planned_change
from safelane.safety._backend import ARRAY
from safelane.sim import _fast_loop
from safelane.sim._alloc import tune_allocator
from safelane.sim._stepper import Stepper
from safelane.sim.inputs import cell_rng, resolve
from safelane.sim.results import results_table
from safelane.sim.scenario import concat, paper_scenarios
from safelane.sim.step import ClosedLoop

VARIANTS = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")


def _plan_speed_change_before(l1_plan, v_x_l, dt, times_s=PLAN_TIMES_S) -> np.ndarray:
    """L1's planned speed change as the feature map took it before: the running sum over the whole plan, every
    horizon's change computed apart (the baseline's; the same values as ``plan_speed_change`` now)."""
    plan_in = np.asarray(l1_plan, dtype=np.float64)
    out = np.zeros((plan_in.shape[0], len(times_s)))
    running = np.cumsum(plan_in, axis=1)
    for j, steps in enumerate(plan_steps(dt, plan_in.shape[1], times_s)):
        if steps > 0:
            out[:, j] = planned_change(ARRAY, running[:, steps - 1], dt, np.asarray(v_x_l, float))
    return out


def _features_before(obs, params) -> np.ndarray:
    """The feature map as it was before: ``features`` with :func:`_plan_speed_change_before`."""
    saved, feature_map.plan_speed_change = feature_map.plan_speed_change, _plan_speed_change_before
    try:
        return feature_map.features(obs, params)
    finally:
        feature_map.plan_speed_change = saved


class _Before:
    """The network behind the baseline's feature map (``MLPPlanner.__call__`` with :func:`_features_before`)."""

    def __init__(self, net):
        self.net, self.__name__ = net, "mlp_paper"

    def __call__(self, obs, params):
        out = self.net.predict(_features_before(obs, params))
        return clip_actions(out[:, 0], out[:, 1], params)


class _KernelClock:
    """``step_kernel`` with the wall and CPU time spent inside it added up (``Stepper`` looks it up at every call;
    the kernel runs in the calling thread)."""

    def __init__(self):
        self.kernel, self.seconds, self.cpu = _fast_loop.step_kernel, 0.0, 0.0

    def __call__(self, *args):
        start, cpu = time.perf_counter(), time.thread_time()
        self.kernel(*args)
        self.seconds += time.perf_counter() - start
        self.cpu += time.thread_time() - cpu


def run_once(batch, prm, cfg, nominal, way: str, clock: _KernelClock):
    """One run of the whole batch as ``simulate_batch`` runs it on the compiled period: ``(table, (wall, CPU),
    step_kernel's (wall, CPU))`` [s]."""
    planner = _Before(nominal) if way == "before" else nominal
    wall, cpu, in_kernel = time.perf_counter(), time.process_time(), (clock.seconds, clock.cpu)
    sim = Stepper(ClosedLoop(batch, 0, prm, cfg, planner), shared_clock=True)
    state = sim.initial_state()
    step = sim.step if way == "before" else sim.advance
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(round(cfg.horizon_s / prm.dt)):
            state = step(state)[0]
    table = results_table(batch, sim.finish(state))
    kernel = (clock.seconds - in_kernel[0], clock.cpu - in_kernel[1])
    return table, (time.perf_counter() - wall, time.process_time() - cpu), kernel


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20_000, help="scenarios in the batch (the four variants' sum)")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each way (best of)")
    args = ap.parse_args()
    tune_allocator()  # as simulate_batch does
    prm, cfg, scenario, nominal, _ = resolve("paper", None, None, None, None)
    each = args.samples // len(VARIANTS)
    batch = concat([paper_scenarios(v, 3, 5.0, each, cell_rng(0, 3, 5.0, 0.0), scenario) for v in VARIANTS])
    clock = _KernelClock()
    _fast_loop.step_kernel = clock
    try:
        run_once(batch.take(np.arange(64)), prm, cfg, nominal, "now", clock)  # load the kernels
        best, tables = {}, {}
        for _ in range(args.repeats):
            for way in ("before", "now"):
                tables[way], spent, kernel = run_once(batch, prm, cfg, nominal, way, clock)
                if way not in best or spent[0] < best[way][0][0]:
                    best[way] = (spent, kernel)
    finally:
        _fast_loop.step_kernel = clock.kernel
    print(f"{len(batch)} scenarios (paper preset, mlp_paper, N = 3, a = 5, {', '.join(VARIANTS)}), "
          f"{round(cfg.horizon_s / prm.dt)} periods; best of {args.repeats}, interleaved")  # fmt: skip
    for way, ((wall, cpu), (k_wall, k_cpu)) in best.items():
        print(f"  {way:6s}: wall {wall:6.2f} s, CPU {cpu:6.2f} s; step_kernel {k_wall:5.2f} s wall, {k_cpu:5.2f} s "
              f"CPU ({100 * k_cpu / cpu:4.1f} % of the CPU); outside it {cpu - k_cpu:5.2f} s CPU")  # fmt: skip
    ((w0, c0), (_, k0)), ((w1, c1), (_, k1)) = best["before"], best["now"]
    print(f"  now/before: wall {w1 / w0:.3f}, CPU {c1 / c0:.3f}, CPU outside step_kernel {(c1 - k1) / (c0 - k0):.3f}")
    same = tables["before"].equals(tables["now"])
    print(f"  tables identical: {same}")


if __name__ == "__main__":
    main()
