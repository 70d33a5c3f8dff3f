"""The realistic world's side in the compiled closed loop (``sim/_fast_world.py``) against the loop period by period
(``SAFELANE_NO_FUSED=1``), in the same run: ``simulate_batch`` of 10,000 scenarios at N = 3 (the paper's four
variants, half of the followers not connected) on the realistic preset's vehicles, with

* the own lane's leader ``L0`` (``own_lane=True``, the shield's own lane on),
* ``L0`` and sensing error (the shield's sensing off: it takes the measurements as exact),
* ``L0``, sensing error and the actuation delay of 0.2 s (the shield's sensing and delay off: the realistic preset's
  world with the shield's sides the compiled period does not take yet),

each timed in CPU seconds of this process (``time.process_time``: on a shared machine the wall clock also counts time
the process waited), the compiled loop first (after a small run that compiles or loads its kernels), and the tables
compared bit for bit. Prints; asserts only the agreement. Run ``python benchmarks/bench_realworld_loop.py [--n 10000]``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before NumPy loads: one-core figures

import argparse
import time

import numpy as np

from safelane.sim import ScenarioConfig, SimConfig, concat, paper_scenarios, simulate_batch
from safelane.sim.preset import load_preset

VARIANTS = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
SETTINGS = {
    "own lane (L0)": SimConfig(own_lane=True),
    "own lane + sensing error": SimConfig(own_lane=True, sensing_error=True, shield_sensing=False),
    "own lane + sensing error + delay 0.2 s": SimConfig(own_lane=True, sensing_error=True, shield_sensing=False,
                                                        actuation_delay_s=0.2, shield_delay=False),
}  # fmt: skip


def batch(n: int):
    cfg = ScenarioConfig(follower_connected_share=0.5)
    per = n // len(VARIANTS)
    return concat([paper_scenarios(v, 3, 5.0, per, np.random.default_rng(k), cfg, first_id=100_000 * k)
                   for k, v in enumerate(VARIANTS)])  # fmt: skip


def timed(b, prm, cfg, no_fused: bool):
    if no_fused:
        os.environ["SAFELANE_NO_FUSED"] = "1"
    else:
        os.environ.pop("SAFELANE_NO_FUSED", None)
    t0 = time.process_time()
    result = simulate_batch(b, seed=1, params=prm, config=cfg)
    return time.process_time() - t0, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000)
    args = parser.parse_args()
    prm = load_preset("realistic").params
    b = batch(args.n)
    for name, cfg in SETTINGS.items():
        timed(batch(64 * len(VARIANTS)), prm, cfg, False)  # compile or load the kernels
        fused_s, fused = timed(b, prm, cfg, False)
        periods_s, periods = timed(b, prm, cfg, True)
        assert fused.engine == "compiled loop", fused.engine_reasons
        assert periods.engine == "period by period"
        same = fused.table.equals(periods.table)
        assert same, name
        print(f"{name:40s} {len(b)} scenarios, N = 3: compiled loop {fused_s:6.2f} s CPU, period by period "
              f"{periods_s:6.2f} s CPU ({periods_s / fused_s:5.1f}x); tables bit for bit: {same}")  # fmt: skip


if __name__ == "__main__":
    main()
