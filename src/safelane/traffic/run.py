"""One traffic-level run (:func:`run_cell`) and a sweep over penetration and demand (:func:`sweep`) through
:func:`safelane.parallel.map_chunks` — each cell in a fresh process (libsumo is a singleton and keeps state past
``close``: :func:`_cell_job`), seeds explicit in every job, so every backend and worker count gives the same
tables."""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict

import numpy as np

from ..params import Params
from . import measures
from .demand import Demand
from .equipped import LaneChanges

#: The columns of a sweep's ``cells.csv`` (one row per run), in order.
CELL_COLUMNS = ("p", "main_vph", "ramp_vph", "demand_vph", "seconds", "warmup_s", "seed", "inserted", "arrived",
                "throughput_vph", "mean_speed_mps", "mean_travel_time_s", "collisions", "collisions_equipped_involved",
                "collisions_equipped_responsible", "collisions_cut_in", "ssm_conflicts", "ssm_ttc", "ssm_drac",
                "ssm_pet", "ssm_equipped_involved", "lc_started", "lc_completed", "lc_aborted", "lc_gave_up",
                "lc_return_max_s", "lc_return_late", "shield_decisions", "shield_calls", "human_lane_changes",
                "leader_braking_limited", "leader_lag_max_m", "others", "lc_duration_s")  # fmt: skip


def run_cell(demand: Demand, params: Params | None = None, *, others: bool = False) -> dict:
    """Run one cell in this process: ``{"row": {CELL_COLUMNS...}, "collisions": [...]}`` (wall time apart, in
    ``"wall_s"``, so that the table does not depend on the machine; the lane changes' own counts in
    ``"lane_changes"``). ``others``: the changers' situation carries the
    world model's other vehicles (:func:`.others.others_record`)."""
    from .world import TrafficWorld

    prm = params or Params()
    t_wall = time.perf_counter()
    tally = measures.Tally(demand.warmup_s)
    referee, seen = measures.Referee(prm.vehicle_length, prm.vehicle_width), set()
    human_changes = limited_before = 0
    with warnings.catch_warnings(), TrafficWorld(demand, prm) as world:
        warnings.simplefilter("ignore")  # geometry warnings of cut-ins: the situation is built with "ignore"
        changes = LaneChanges(world, prm, others=others)
        steps = round(demand.seconds / prm.dt)
        for _ in range(steps):
            t = world.time()
            departed = world.api.simulation.getDepartedIDList()
            fleet = world.read()
            tally.departed(t, departed)
            tally.speeds(t, fleet.v)
            new = referee.observe(t, fleet)  # (and the last step's collisions judged with the entries it made)
            if t < demand.warmup_s:
                limited_before = world.limited_steps
            else:
                human_changes += sum(1 for e in new if not e["vid"].startswith("cav."))
            if len(fleet):
                changes.period(fleet, t)
            world.step()
            tally.arrivals(world.time(), world.arrived())
            for c in world.collisions():
                pair = (c["collider"], c["victim"])
                if pair not in seen:
                    seen.add(pair)
                    if c["t"] >= demand.warmup_s:
                        referee.collided([c])
            if world.api.simulation.getMinExpectedNumber() == 0 and t > demand.warmup_s:
                break
        if referee.pending:  # a collision in the last step: judged with the state it left
            referee.observe(world.time(), world.read())
        collisions = referee.judged
        inserted, limited, lag = tally.inserted, world.limited_steps - limited_before, world.max_lag_m
        world.close()
        conflicts = measures.ssm_conflicts(world.ssm_file, demand.warmup_s)
    span_h = (demand.seconds - demand.warmup_s) / 3600.0
    cav = lambda vid: vid.startswith("cav.")  # noqa: E731
    c = changes.counts
    row = {
        **{k: v for k, v in asdict(demand).items() if k != "p"}, "p": demand.p, "demand_vph": demand.total_vph,
        "inserted": inserted, "arrived": tally.arrived, "throughput_vph": tally.arrived / span_h,
        "mean_speed_mps": tally.mean_speed,
        "mean_travel_time_s": float(np.mean(tally.travel)) if tally.travel else np.nan,
        "collisions": len(collisions),
        "collisions_equipped_involved": sum(cav(x["collider"]) or cav(x["victim"]) for x in collisions),
        "collisions_equipped_responsible": sum(cav(x["responsible"]) for x in collisions),
        "collisions_cut_in": sum(x["rule"] == "cut-in" for x in collisions),
        "ssm_conflicts": len(conflicts), "ssm_ttc": sum(r["ttc"] < 1.5 for r in conflicts),
        "ssm_drac": sum(r["drac"] > 3.35 for r in conflicts), "ssm_pet": sum(r["pet"] < 1.0 for r in conflicts),
        "ssm_equipped_involved": sum(cav(r["ego"]) or cav(r["foe"]) for r in conflicts),
        "lc_started": c["started"], "lc_completed": c["completed"], "lc_aborted": c["aborted"],
        "lc_gave_up": c["gave_up"], "lc_return_max_s": c["return_max_s"], "lc_return_late": c["return_late"],
        "shield_decisions": c["decisions"], "shield_calls": c["shield_calls"],
        "human_lane_changes": human_changes, "leader_braking_limited": limited,
        "leader_lag_max_m": lag, "others": bool(others),
    }  # fmt: skip
    row = {k: row[k] for k in CELL_COLUMNS}
    return {"row": row, "collisions": [{"p": demand.p, "demand_vph": demand.total_vph, **x} for x in collisions],
            "wall_s": time.perf_counter() - t_wall, "steps": steps, "lane_changes": dict(c)}  # fmt: skip


def _cell_job(job: dict) -> dict:
    """A sweep's job (module level: Ray workers import it by name): :func:`run_cell` in a fresh process of its own.

    libsumo keeps some state past ``close()``: in one process, the same cell gives other tables when another run
    went before it (measured: p 0.5, 2,500 veh/h, 40 s, seed 3 — 606 shield decisions and 17 human lane changes
    as the process's first run, 593 and 14 after any other run, with the compiled kernels or without, before and after
    the braking limit). So that a cell's tables depend neither on the backend nor on which cells its worker ran
    before, every cell starts from a fresh interpreter (``spawn``; a second or so against minutes of simulation)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    job = dict(job)
    others = bool(job.pop("others", False))
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(run_cell, Demand(**job), others=others).result()


def cells(penetrations, demands_vph, *, seconds: float, warmup_s: float, seed: int, ramp_share: float = 0.15,
          others: bool = False, lc_duration_s: float = 0.0) -> list[dict]:  # fmt: skip
    """The jobs of a sweep: every penetration × total demand (the ramp takes ``ramp_share`` of it), one seed for all
    (the same arrivals at every penetration: common random numbers); ``others`` (the world model's feed) and
    ``lc_duration_s`` (SUMO's continuous lane changes, :class:`.demand.Demand`) the same in every cell."""
    return [{"p": float(p), "main_vph": float(q) * (1 - ramp_share), "ramp_vph": float(q) * ramp_share,
             "seconds": float(seconds), "warmup_s": float(warmup_s), "seed": int(seed), "others": bool(others),
             "lc_duration_s": float(lc_duration_s)}
            for q in demands_vph for p in penetrations]  # fmt: skip


def sweep(jobs: list[dict], backend="process", workers: int | None = None, ray_address: str | None = None):
    """``(cells table, collisions table, wall seconds per job)``: :func:`run_cell` of every job on ``backend``, each in
    a fresh process (:func:`_cell_job`). The processes are started with ``spawn``, which imports the calling script's
    main module again: a script that calls this needs the usual ``if __name__ == "__main__":`` guard."""
    import pandas as pd

    from ..parallel import map_chunks

    out = map_chunks(_cell_job, jobs, backend, workers, ray_address)
    table = pd.DataFrame([o["row"] for o in out], columns=list(CELL_COLUMNS))
    cols = ["p", "demand_vph", "t", "collider", "victim", "type", "lane", "pos", "collider_speed", "victim_speed",
            "responsible", "rule"]  # fmt: skip
    coll = pd.DataFrame([x for o in out for x in o["collisions"]], columns=cols)
    return table, coll, [o["wall_s"] for o in out]
