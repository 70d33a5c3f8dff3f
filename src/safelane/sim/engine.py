"""The batched closed-loop simulator: one state of arrays, a Python loop over time steps only.

``simulate`` runs one experiment cell; ``simulate_batch`` runs any :class:`ScenarioBatch` (a whole grid of
cells is just a bigger batch) — in one process, or split into chunks on worker processes or a Ray cluster
(:func:`safelane.parallel.map_chunks`). One period of the loop is
:meth:`safelane.sim.step.ClosedLoop.step`.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np
from threadpoolctl import threadpool_limits

from ..errors import InputError
from ..parallel import Backend, as_backend, map_chunks
from ..params import Params
from ..planners.base import ExpertPlanner, NominalPlanner
from . import _fused as fused
from . import blame_log
from ._alloc import tune_allocator
from ._stepper import Stepper
from .config import SimConfig
from .inputs import cell_rng, check_cell_args, check_settings, resolve
from .results import SimResult, results_table, trace_rows
from .scenario import ScenarioBatch, ScenarioConfig, check_batch, paper_scenarios
from .step import ClosedLoop

if TYPE_CHECKING:  # pandas loads with the first table, not with the package
    import pandas as pd


def simulate(
    planner: str = "CV_all",
    n_leaders: int = 5,
    decel: float = 5.0,
    samples: int = 1000,
    seed: int = 0,
    *,
    p_v: float = 0.0,
    params: Params | None = None,
    config: SimConfig | None = None,
    scenario: ScenarioConfig | None = None,
    nominal: NominalPlanner | str | None = None,
    trace: bool = False,
    record_observations: bool = False,
    progress: bool = False,
    preset: str | None = None,
    trace_limit: int = 16,
    traffic=None,
    workers: int | Backend = 1,
    blame: bool = False,
) -> SimResult:
    """Simulate one experiment cell of the paper's sampler.

    ``preset`` (a name such as ``"paper"``, a YAML path or a ``Preset``) supplies ``params``, ``config`` and the
    nominal planner where those are not given; ``nominal`` takes a registered name (``"mlp"``) or the path of a
    model file (``"model.npz"`` as ``safelane train`` writes it, or ``.onnx``). The cell's
    scenarios come from :func:`~safelane.sim.inputs.cell_rng`, as in ``safelane reproduce``: the same cell and
    seed give the same numbers as the report. Bad arguments raise ``InputError`` naming the argument. ``traffic``,
    ``workers`` and ``blame``: as for :func:`simulate_batch`.

    Example: ``simulate("CV_all", n_leaders=5, decel=5.0, samples=1000, seed=0).summary()``.
    """
    check_cell_args(planner, n_leaders, decel, samples, seed, p_v)
    params, config, scenario, nominal, labels = resolve(preset, params, config, scenario, nominal)
    rng = cell_rng(seed, n_leaders, decel, p_v)
    batch = paper_scenarios(planner, n_leaders, decel, samples, rng, scenario, p_v=p_v)
    result = simulate_batch(
        batch,
        seed=seed,
        params=params,
        config=config,
        nominal=nominal,
        trace=trace,
        record_observations=record_observations,
        progress=progress,
        trace_limit=trace_limit,
        traffic=traffic,
        workers=workers,
        blame=blame,
    )
    result.preset, result.nominal = labels["preset"], labels["nominal"]  # named in result.summary()
    return result


def simulate_batch(
    batch: ScenarioBatch,
    seed: int = 0,
    *,
    params: Params | None = None,
    config: SimConfig | None = None,
    nominal: NominalPlanner | None = None,
    trace: bool = False,
    record_observations: bool = False,
    progress: bool = False,
    trace_limit: int = 16,
    workers: int | Backend = 1,
    traffic=None,
    blame: bool = False,
) -> SimResult:
    """Run every scenario of ``batch`` in closed loop; see :class:`SimResult`.

    ``workers > 1`` splits the batch across processes, and a :class:`~safelane.parallel.Backend` (e.g.
    ``Backend("ray", 8)``) into chunks on that backend; scenarios are independent and their random draws are
    counter-based, so the table is identical, bit for bit, to a single-process run (traces and observations are
    recorded in this process only: with them the batch runs here). ``traffic``: the target-lane traffic — a
    registered name (``safelane.sim.traffic.TRAFFIC_MODELS``), a :class:`~safelane.sim.traffic.TrafficModel`, or
    :class:`~safelane.sim.traffic.TrafficHooks` (the paper's model with some wishes replaced); with workers it must be
    picklable and index per-scenario data by ``scenario_id``. ``blame``: add who is responsible for each scenario's
    first collision and first ``p_m`` violation (:mod:`.blame_log`: ``collision_blame``, ``pm_blame``, their clause,
    blame time and partner; ``summary()`` then reports the ego's share beside each total). The compiled loop does not
    record it: its rows with an event are run again period by period (the same scenarios, the same bits).
    """
    prm = params or Params()
    cfg = config or SimConfig()
    nominal = nominal or ExpertPlanner()
    check_batch(batch, prm)
    check_settings(prm, cfg)
    tune_allocator()
    backend = as_backend(workers)
    if not (trace or record_observations) and not backend.in_process:
        chunks = min(backend.parallelism(), len(batch) // 2)
        if chunks > 1 or (chunks == 1 and backend.name == "ray"):  # Ray: the driver may be a laptop
            return _simulate_parallel(batch, seed, prm, cfg, nominal, backend, chunks, traffic, blame)
    sim = ClosedLoop(batch, seed, prm, cfg, nominal, traffic, blame=blame or None)
    n_steps = round(cfg.horizon_s / prm.dt)
    why = fused.reasons(batch, cfg, nominal, traffic, trace, record_observations)
    if blame and not fused.chunkable(sim):  # (the blame's rerun rebuilds rows with the defaults)
        why = [*why, "blame with traffic hooks or a planner with per-row parameters"]
    if not why:  # the whole run compiled
        table = results_table(batch, fused.run(sim, n_steps, progress))
        if blame:
            table = _blame_again(table, ClosedLoop(batch, seed, prm, cfg, nominal, traffic, blame=True), n_steps)
        return SimResult(table=table, engine="compiled loop")
    engine = "period by period"
    if not blame and not fused.reasons(batch, cfg, nominal, traffic, False, False, stepping=True):
        # Everything but the nominal planner, the trace or the observations is compiled: the periods run compiled,
        # the planner between them on the observation (any planner), the trace and observations from the state.
        sim, engine = Stepper(sim, shared_clock=True), "compiled period"
    elif os.environ.get("SAFELANE_REQUIRE_COMPILED", "") == "1":
        raise InputError(f"SAFELANE_REQUIRE_COMPILED=1 but this run is not compiled: {'; '.join(why)}",
                         "SAFELANE_REQUIRE_COMPILED")  # fmt: skip
    state = sim.initial_state()
    rows, observations = [], []
    steps = range(n_steps)
    if progress:
        from .._progress import track

        steps = track(steps, f"simulating {len(batch)} scenarios")
    # The batch is elementwise NumPy plus small matrix products (NN planners): BLAS threads only oversubscribe
    # the cores (and the worker processes), so they are limited to one for the run.
    # The loop keeps no earlier state: the compiled periods advance the rows in place (Stepper.advance), where
    # Stepper.step would copy the whole state every period to keep the state before it.
    advance = sim.advance if isinstance(sim, Stepper) else sim.step
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in steps:
            state, obs, behaviour = advance(state)
            if record_observations:
                observations.append(obs)
            if trace:
                rows.append(trace_rows(batch, state, behaviour, trace_limit))
    state = sim.finish(state)
    table = results_table(batch, state)
    import pandas as pd

    trace_df = pd.concat(rows, ignore_index=True) if trace and rows else None
    return SimResult(table=table, trace=trace_df, observations=observations, engine=engine,
                     engine_reasons=tuple(why))  # fmt: skip


def _blame_again(table: pd.DataFrame, sim: ClosedLoop, n_steps: int) -> pd.DataFrame:
    """``table`` (the compiled loop's) with the blame columns: the rows with a collision or a ``p_m`` violation run
    again period by period with the blame rule's followers (``sim``: the whole batch, ``blame=True``); every other
    row has no event to blame. The rerun must reproduce the compiled loop's outcomes."""
    rows = np.flatnonzero(table["collision"].to_numpy() | table["safety_violation"].to_numpy())
    out = table.assign(**blame_log.no_events(len(table)))
    if rows.size == 0:
        return out
    again = ClosedLoop(sim.b.take(rows), sim.seed, sim.prm, sim.cfg, sim.nominal, None, blame=sim.blame)
    state = again.initial_state()
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(n_steps):
            state = again.step(state)[0]
    part = results_table(again.b, again.finish(state))
    for col in ("collision", "safety_violation"):
        if not np.array_equal(part[col].to_numpy(), table[col].to_numpy()[rows]):
            raise RuntimeError(f"the period-by-period rerun for the blame columns disagrees with the compiled loop on "
                               f"{col!r}: a bug (the two engines must give the same bits)")  # fmt: skip
    for col in blame_log.no_events(0):
        out.loc[rows, col] = part[col].to_numpy()
    return out


def _simulate_chunk(args) -> pd.DataFrame:
    batch, seed, prm, cfg, nominal, traffic, blame = args
    return simulate_batch(batch, seed, params=prm, config=cfg, nominal=nominal, traffic=traffic, blame=blame).table


def _simulate_parallel(batch, seed, prm, cfg, nominal, backend: Backend, chunks: int, traffic=None,
                       blame: bool = False) -> SimResult:  # fmt: skip
    parts = np.array_split(np.arange(len(batch)), chunks)
    jobs = [(batch.take(rows), seed, prm, cfg, nominal, traffic, blame) for rows in parts]
    tables = map_chunks(_simulate_chunk, jobs, backend)
    import pandas as pd

    return SimResult(table=pd.concat(tables, ignore_index=True))
