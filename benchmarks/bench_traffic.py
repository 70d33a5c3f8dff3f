"""Shielded decisions per second against libsumo's own step cost, with 100, 1,000 and 5,000 vehicles in the network
(safelane.traffic; docs/traffic.md). Same run, same process, for each size:

* SUMO: ``simulationStep`` of the long merge network (``merge3_long.net.xml``) holding that many vehicles (half of
  them equipped, spread over the 40 km downstream section at 20 m/s), the mean over ``--steps`` steps; ``+SSM``: the
  same with SUMO's SSM device on every vehicle, as ``safelane traffic`` runs it (for its conflicts);
* reading the fleet (subscriptions), which any TraCI client pays, shielded or not;
* the shield's share of a period, for every equipped vehicle in lanes 1–2 treated as changing left (a batch of about
  a third of the fleet): building the changers' batch ``Situation`` from the fleet's arrays, and ``Shield.step``
  over it after ``init``, each the mean over ``--steps`` periods, interleaved with SUMO's steps (each period: SUMO's
  step, the read, the situation, the shield's step) so that all see the same state of the machine; decisions per
  second = rows / (situation + step);
  ``shield/SUMO`` = (situation + step) over SUMO's step without the SSM device (the cheaper one).

``--live D [D ...]``: the study's own runs instead — the shipped merge network (SSM device on, SUMO's lane changing
and the ramp's merges) at each total demand ``D`` [veh/h] and penetration ``--p``, ``--seconds`` simulated after
``--warmup``, every component timed in place over the run's periods: SUMO's step, the read, the changers'
``Situation``, ``Shield.step`` (with the pool's bookkeeping) and the rest of the traffic layer's period (wishes,
planner, placing the changers, the leaders' braking limit); the mean vehicles in the network and changers per period.

    .venv/bin/python benchmarks/bench_traffic.py [--sizes 100 1000 5000] [--steps 20]
    .venv/bin/python benchmarks/bench_traffic.py --live 2500 4900 [--p 1] [--seconds 200] [--warmup 100]
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np


def routes(n: int, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    pos = np.sort(rng.uniform(50.0, 38_500.0, n))
    lines = ['<routes><vType id="human" length="4.8" width="1.8" sigma="0.5" emergencyDecel="8"/>',
             '<vType id="cav" length="4.8" width="1.8" sigma="0" emergencyDecel="8"/>', '<route id="r" edges="out"/>']
    for k, x in enumerate(pos.tolist()):
        kind = "cav" if k % 2 else "human"
        lines.append(f'<vehicle id="{kind}.{k}" type="{kind}" route="r" depart="0" departLane="{k % 3}" '
                     f'departPos="{x:.1f}" departSpeed="20" insertionChecks="none"/>')  # fmt: skip
    return "\n".join([*lines, "</routes>"]) + "\n"


def sumo_with_ssm_ms(n: int, steps: int) -> float:
    """SUMO's step as the study runs it (its SSM device on every vehicle, ``safelane traffic``'s conflicts): the mean
    over ``steps`` steps of the same network and vehicles, nobody shielded."""
    from safelane import Params
    from safelane.traffic.demand import Demand, net_file
    from safelane.traffic.world import TrafficWorld

    with TrafficWorld(Demand(p=0.5, seconds=600, warmup_s=1), Params(), net=net_file(long=True), routes=routes(n),
                      ssm=True) as world:  # fmt: skip
        world.step()
        world.read()
        t = 0.0
        for _ in range(steps):
            t0 = time.perf_counter()
            world.step()
            t += time.perf_counter() - t0
            world.read()
    return 1e3 * t / steps


def bench(n: int, steps: int) -> dict:
    from safelane import Params
    from safelane.traffic.demand import Demand, net_file
    from safelane.traffic.equipped import LaneChanges
    from safelane.traffic.shielding import decide
    from safelane.traffic.world import TrafficWorld

    prm = Params()
    with TrafficWorld(Demand(p=0.5, seconds=600, warmup_s=1), prm, net=net_file(long=True), routes=routes(n),
                      ssm=False) as world:  # fmt: skip
        world.step()
        fleet = world.read()
        changes = LaneChanges(world, prm)
        sel = np.flatnonzero(fleet.equipped & (fleet.lane >= 1) & (fleet.lane <= 2))
        b = len(sel)
        changes.ids = [fleet.ids[i] for i in sel]
        changes.g0, changes.sign = fleet.lane[sel], np.ones(b)
        changes.ex, changes.ey, changes.evx, changes.evy = fleet.x[sel], np.zeros(b), fleet.v[sel], np.zeros(b)
        changes.ret, changes.t_done = np.zeros(b, bool), np.full(b, np.nan)  # changes under way
        situation, chain = changes.situation(fleet, fleet.x, sel, world.time())  # first call: imports, compiles
        proposal = changes.planner(changes._observation(situation, fleet, chain, np.zeros(b, bool)), prm)
        decide(changes.pool, situation, proposal, np.zeros(0, np.int64), b)  # init + first step
        snapshot = fleet
        t_sumo = t_read = t_sit = t_shield = 0.0
        # interleaved, period by period as in a run, so that both sides see the same state of the machine: SUMO steps
        # and is read; the shield's changers stay the same, their situation rebuilt and decided every period
        for _ in range(steps):
            t0 = time.perf_counter()
            world.step()
            t1 = time.perf_counter()
            fleet = world.read()
            t2 = time.perf_counter()
            situation, chain = changes.situation(snapshot, snapshot.x, sel, world.time())
            t3 = time.perf_counter()
            decide(changes.pool, situation, proposal, np.arange(b), 0)
            t4 = time.perf_counter()
            t_sumo, t_read, t_sit, t_shield = t_sumo + t1 - t0, t_read + t2 - t1, t_sit + t3 - t2, t_shield + t4 - t3
        t_sumo, t_read, t_sit, t_shield = (t / steps for t in (t_sumo, t_read, t_sit, t_shield))
    return {"vehicles": len(fleet), "sumo_step_ms": 1e3 * t_sumo, "read_ms": 1e3 * t_read,
            "situation_ms": 1e3 * t_sit, "batch": b, "shield_step_ms": 1e3 * t_shield,
            "decisions_per_s": b / (t_sit + t_shield), "ratio": (t_sit + t_shield) / t_sumo}  # fmt: skip


def live(demand_vph: float, p: float, seconds: float, warmup: float) -> dict:
    """One run of the study (:func:`safelane.traffic.run.run_cell`) with its components timed in place (wrapped);
    the means are per period after ``warmup``."""
    from safelane.traffic import equipped, run, world
    from safelane.traffic.demand import Demand

    wall = {"sumo": 0.0, "read": 0.0, "situation": 0.0, "shield": 0.0, "period": 0.0}
    tally = {"periods": 0, "vehicles": 0, "changers": 0}
    clock = {"t": 0.0}

    def timed(name, fn, after=None):
        def wrapper(*a, **k):
            t0 = time.perf_counter()
            out = fn(*a, **k)
            if clock["t"] >= warmup:
                wall[name] += time.perf_counter() - t0
                if after:
                    after(a, out)
            return out

        return wrapper

    def read_counted(a, fleet):
        tally["periods"] += 1
        tally["vehicles"] += len(fleet)

    def decided(a, decision):
        tally["changers"] += len(decision.a_x)

    saved = (world.TrafficWorld.step, world.TrafficWorld.read, equipped.LaneChanges.situation, equipped.decide,
             equipped.LaneChanges.period)  # fmt: skip

    def read(self):
        clock["t"] = self.time()
        return timed("read", saved[1], read_counted)(self)

    world.TrafficWorld.step = timed("sumo", saved[0])
    world.TrafficWorld.read = read
    equipped.LaneChanges.situation = timed("situation", saved[2])
    equipped.decide = timed("shield", saved[3], decided)
    equipped.LaneChanges.period = timed("period", saved[4])
    try:
        run.run_cell(Demand(p=p, main_vph=0.85 * demand_vph, ramp_vph=0.15 * demand_vph, seconds=warmup + seconds,
                            warmup_s=warmup, seed=0))  # fmt: skip
    finally:
        (world.TrafficWorld.step, world.TrafficWorld.read, equipped.LaneChanges.situation, equipped.decide,
         equipped.LaneChanges.period) = saved  # fmt: skip
    n = max(tally["periods"], 1)
    ms = {k: 1e3 * v / n for k, v in wall.items()}
    rest = ms["period"] - ms["situation"] - ms["shield"]
    return {"demand": demand_vph, "vehicles": tally["vehicles"] / n, "changers": tally["changers"] / n, **ms,
            "rest": rest, "ratio": (ms["situation"] + ms["shield"]) / ms["sumo"]}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 5000])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--live", type=float, nargs="+", help="total demands [veh/h]: time the study's own runs")
    ap.add_argument("--p", type=float, default=1.0)
    ap.add_argument("--seconds", type=float, default=200.0)
    ap.add_argument("--warmup", type=float, default=100.0)
    args = ap.parse_args()
    if args.live:
        print(f"{'veh/h':>6} {'vehicles':>8} {'changers':>8} {'SUMO step ms':>12} {'read ms':>8} {'situation ms':>12} "
              f"{'shield step ms':>14} {'rest ms':>8} {'shield/SUMO':>11}")  # fmt: skip
        for q in args.live:  # each run in a fresh interpreter, as the sweep's (libsumo keeps state past close)
            with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
                r = pool.submit(live, q, args.p, args.seconds, args.warmup).result()
            print(f"{r['demand']:>6.0f} {r['vehicles']:>8.0f} {r['changers']:>8.1f} {r['sumo']:>12.2f} "
                  f"{r['read']:>8.2f} {r['situation']:>12.2f} {r['shield']:>14.2f} {r['rest']:>8.2f} "
                  f"{r['ratio']:>11.2f}")  # fmt: skip
        return
    print(f"{'vehicles':>8} {'SUMO step ms':>12} {'+SSM ms':>8} {'read ms':>8} {'situation ms':>12} {'batch':>6} "
          f"{'shield step ms':>14} {'decisions/s':>11} {'shield/SUMO':>11}")  # fmt: skip
    for n in args.sizes:
        r = bench(n, args.steps)
        ssm = sumo_with_ssm_ms(n, args.steps)
        print(f"{r['vehicles']:>8} {r['sumo_step_ms']:>12.2f} {ssm:>8.2f} {r['read_ms']:>8.2f} "
              f"{r['situation_ms']:>12.2f} {r['batch']:>6} {r['shield_step_ms']:>14.2f} {r['decisions_per_s']:>11.0f} "
              f"{r['ratio']:>11.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
