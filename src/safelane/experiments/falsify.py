"""Adversarial falsifier: search behaviours *inside* the paper's assumptions for a collision or a ``p_m`` violation.

What is searched (the spec of :mod:`safelane.experiments.falsify_space`): initial states at the edges (tiny and
zero slacks, speed ties, partly changed lanes, lateral speed, N = 0..10, human-driven leaders, every variant),
L(N+1) piecewise-constant acceleration profiles, the connected leaders' own tasks anywhere inside their promises
and F's wish anywhere inside its type's range (through the public :class:`~safelane.sim.traffic.TrafficHooks`),
and adversarial nominal planners (:mod:`safelane.planners.adversarial`). The assessment is the truth (the
guarantee assumes an accurate one) and ``p_v = 0``.

How (each method a stream of batches; ``method="all"`` takes them in turn):

* ``random`` — uniform points of the unit cube, decoded with edge mixtures;
* ``cem`` — a cross-entropy optimiser in the unit cube minimising the smallest gap over its margin (independent
  Gaussians, elite share 10 %, smoothed updates, restarts when it has converged);
* ``knife`` — targeted knife-edge families (:func:`~safelane.experiments.falsify_space.knife_specs`).

Everything is seeded: batch ``i`` of method ``m`` in stream ``w`` draws from ``default_rng([seed, w, m, i])``; with
``minutes=0`` the run is a function of ``(seed, scenarios, method, batch_size, workers)`` alone. Each simulation runs
in one process (``simulate_batch(workers=1)``: the adversarial planners index per-scenario parameters by batch row);
``workers > 1`` runs that many independent streams in parallel processes and merges their reports; a
:class:`~safelane.parallel.Backend` runs them on that backend (``Backend("ray", 16)``: 16 streams as Ray tasks; the
report is the same as with 16 processes).
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..parallel import Backend, as_backend, map_chunks
from ..params import Params
from ..sim.config import SimConfig
from ..sim.engine import simulate_batch
from ..sim.step import ClosedLoop
from . import falsify_build as built
from . import falsify_space as space
from .falsify_report import NOTES, OUTCOMES, Report, json_scalar, merge, scenario_record  # noqa: F401

METHODS = ("random", "cem", "knife")


def hooks_live() -> bool:
    """Whether :func:`simulate_batch` accepts ``traffic=`` yet (the extension point is being wired)."""
    import inspect

    return "traffic" in inspect.signature(simulate_batch).parameters


class LaneGapRecorder:
    """Running minimum of each scenario's target-lane gaps over their margins (F–L1, L_i–L(i+1)), sampled at the
    start of every period by the traffic hooks (:func:`~.falsify_build.hooks_for`: ``WaveHooks``, which the compiled
    closed loop samples as the NumPy path does). The exact in-period check is the simulator's ``leader_violation``;
    this sample only ranks scenarios for the optimiser."""

    def __init__(self, batch, prm: Params):
        self.margin = np.where(batch.human, prm.p_m_human, prm.p_m)[:, :-1]
        self.pairs = batch.valid[:, 1:] & batch.valid[:, :-1]
        self.min_ratio = np.full(len(batch), np.inf)


@dataclass(frozen=True)
class Setting:
    """What every evaluation shares: limits, simulation settings, and what lies outside the assumptions."""

    params: Params = field(default_factory=Params)
    sim: SimConfig = field(default_factory=lambda: SimConfig(assessment="truth"))
    seed: int = 0
    decel_last_max: float | None = None  # > a_x_d: L(N+1) may brake beyond the assumptions (studies, tests)
    use_hooks: bool = True  # traffic hooks, where the simulator has them
    use_profiles: bool = True  # L(N+1) profiles, where the simulator has them (else sudden braking at decel_last)
    world: str = "paper"  # "realistic": L0, sensing errors, actuation delay (docs/real_roads.md; falsify_space.WORLDS)

    @classmethod
    def realistic(cls, **kwargs) -> Setting:
        """The realistic world (docs/real_roads.md): an own-lane leader L0 from the spec, measurement errors in their
        bounds (half of them at the bounds' ends), the delay from the spec; the extended shield."""
        sim = SimConfig(assessment="truth", own_lane=True, sensing_error=True, sensing_edge_share=0.5)
        return cls(sim=sim, world="realistic", **kwargs)

    def resolved(self) -> Setting:
        """This setting with ``use_hooks`` / ``use_profiles`` saying what this simulator really does (dumps record
        it, so a replay on a newer simulator uses the same behaviour models)."""
        return dataclasses.replace(
            self,
            use_hooks=self.use_hooks and hooks_live(),
            use_profiles=self.use_profiles and built.with_profile_fields() and self.decel_last_max is None,
        )


def evaluate(spec: dict, setting: Setting) -> tuple[pd.DataFrame, dict]:
    """Simulate every row of ``spec`` that satisfies the assumptions at ``t = 0``; returns one outcome row per
    simulated scenario (``row``: its index in ``spec``) and the kept spec rows."""
    prm = setting.params
    spec = dict(spec)
    if setting.decel_last_max is not None:
        spec["decel_last"] = spec["decel_last"] / prm.a_x_d * setting.decel_last_max
    setting = setting.resolved()
    hooks, profiles = setting.use_hooks, setting.use_profiles
    batch, ok = built.build(spec, prm, profiles=profiles)
    keep = np.flatnonzero(ok)
    frames = []
    delay = spec.get("delay_periods", np.zeros(len(ok), np.int64))
    groups = {(float(a), int(d)) for a, d in zip(spec["brake_start_s"][keep], delay[keep], strict=True)}
    for start, periods in sorted(groups):
        rows = keep[(spec["brake_start_s"][keep] == start) & (delay[keep] == periods)]
        sub = dataclasses.replace(batch.take(rows), scenario_id=np.arange(rows.size, dtype=np.int64))
        sub_spec = space.take(spec, rows)
        update = {"brake_start_s": float(start)}
        if "delay_periods" in spec:
            update["actuation_delay_s"] = periods * prm.dt
        cfg = setting.sim.model_copy(update=update)
        if "world_key" in spec:  # drop, before simulating, the rows the shield's own initial check rejects
            start = ClosedLoop(sub, setting.seed, prm, cfg, built.planner_for(sub_spec, prm)).initial_state()
            inside = np.flatnonzero(start.initial_safe)
            if inside.size < rows.size:
                rows = rows[inside]
                sub = dataclasses.replace(batch.take(rows), scenario_id=np.arange(rows.size, dtype=np.int64))
                sub_spec = space.take(spec, rows)
            if rows.size == 0:
                continue
        kwargs = {}
        recorder = None
        if hooks:
            recorder = LaneGapRecorder(sub, prm)
            kwargs["traffic"] = built.hooks_for(sub_spec, prm, recorder, k=sub.x.shape[1])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # decel_last beyond a_x_d is intended where it is asked for
            table = simulate_batch(
                sub, setting.seed, params=prm, config=cfg, nominal=built.planner_for(sub_spec, prm), workers=1, **kwargs
            ).table
        out = pd.DataFrame({"row": rows})
        for name in OUTCOMES:
            out[name] = table[name].to_numpy(bool)
        for name in NOTES:
            out[name] = table[name].to_numpy(np.int64) if name in table else 0
        out["ratio_l1"] = table["min_gap_leader_m"].to_numpy() / prm.p_m
        out["ratio_f"] = table["min_gap_follower_m"].to_numpy() / prm.p_m
        if "min_gap_own_lane_m" in table:
            out["ratio_f"] = np.fmin(out["ratio_f"], table["min_gap_own_lane_m"].to_numpy() / prm.p_m)
        out["lane_ratio"] = recorder.min_ratio if recorder is not None else np.nan
        # The shield's own check at t = 0 (with L0, errors and delay) decides what starts inside the assumptions.
        out = out[table["initial_safe"].to_numpy(bool)] if "initial_safe" in table else out
        frames.append(out)
    outcome = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["row", *OUTCOMES])
    outcome["ratio"] = np.fmin(outcome["ratio_l1"], outcome["ratio_f"]) if len(outcome) else []
    outcome = outcome.sort_values("row", ignore_index=True)
    return outcome, space.take(spec, outcome["row"].to_numpy(np.int64))


def evaluate_round(specs: list[dict], setting: Setting) -> tuple[list[pd.DataFrame], list[dict]]:
    """:func:`evaluate` of each spec of ``specs``, simulated as one batch: per spec its outcome (``row``: its index in
    that spec) and its kept rows, as :func:`evaluate` gives them for that spec alone."""
    sizes = [len(s["n"]) for s in specs]
    outcome, _ = evaluate(space.concat_specs(specs), setting)
    rows = outcome["row"].to_numpy(np.int64)
    edges = np.cumsum([0, *sizes])
    outcomes, kept = [], []
    for spec, lo, hi in zip(specs, edges[:-1], edges[1:], strict=True):
        part = outcome[(rows >= lo) & (rows < hi)].reset_index(drop=True)
        part["row"] = part["row"].to_numpy(np.int64) - lo
        outcomes.append(part)
        kept.append(space.take(spec, part["row"].to_numpy(np.int64)))
    return outcomes, kept


def score(outcome: pd.DataFrame) -> np.ndarray:
    """What the optimiser minimises: the smallest gap over its margin (ego and sampled lane gaps); a collision or
    violation scores below any gap, a scenario that never entered the conflict zone scores 3."""
    s = np.fmin(outcome["ratio"].to_numpy(float), outcome["lane_ratio"].to_numpy(float))
    s = np.where(np.isnan(s), 3.0, np.minimum(s, 3.0))
    bad = outcome[list(OUTCOMES)].to_numpy(bool).any(1)
    return np.where(bad, s - 10.0, s)


class CrossEntropy:
    """Cross-entropy search in the unit cube (independent Gaussians, clipped): each generation samples
    ``population`` points, keeps the best ``elite`` share by :func:`score` and moves mean and spread toward them
    (smoothing ``alpha``); it restarts from the prior when the spread has collapsed or after ``max_generations``."""

    def __init__(self, dim: int, elite: float = 0.1, alpha: float = 0.7, max_generations: int = 25):
        self.dim, self.elite, self.alpha, self.max_generations = dim, elite, alpha, max_generations
        self.restart()

    def restart(self) -> None:
        self.mean, self.std, self.generation = np.full(self.dim, 0.5), np.full(self.dim, 0.35), 0

    def ask(self, rng: np.random.Generator, population: int) -> np.ndarray:
        if self.generation >= self.max_generations or self.std.mean() < 0.02:
            self.restart()
        self.generation += 1
        return np.clip(self.mean + self.std * rng.standard_normal((population, self.dim)), 0.0, 1.0)

    def tell(self, u: np.ndarray, scores: np.ndarray) -> None:
        finite = np.isfinite(scores)
        if finite.sum() < 4:
            return
        order = np.argsort(np.where(finite, scores, np.inf), kind="stable")[: max(2, int(self.elite * finite.sum()))]
        best = u[order]
        self.mean = self.alpha * best.mean(0) + (1 - self.alpha) * self.mean
        self.std = self.alpha * best.std(0) + (1 - self.alpha) * self.std


def replay(record: dict | str | Path) -> pd.DataFrame:
    """Re-simulate a dumped scenario (a :func:`scenario_record` or the path of its JSON); returns its outcome row."""
    if not isinstance(record, dict):
        record = json.loads(Path(record).read_text())
    spec = {k: np.asarray([v]) for k, v in record["spec"].items()}
    setting = Setting(
        params=Params(**record["params"]),
        sim=SimConfig(**record["sim"]),
        seed=record["seed"],
        decel_last_max=record["decel_last_max"],
        use_hooks=record["use_hooks"],
        use_profiles=record.get("use_profiles", record["use_hooks"]),
    )
    return evaluate(spec, setting)[0]


def falsify(
    scenarios: int,
    minutes: float = 0.0,
    seed: int = 0,
    method: str = "all",
    *,
    batch_size: int = 2048,
    setting: Setting | None = None,
    on_batch: Callable[[Report], None] | None = None,
    workers: int | Backend = 1,
    stream: int = 0,
) -> Report:
    """Run the falsifier until at least ``scenarios`` scenarios have been simulated *and* ``minutes`` have passed.

    ``method``: one of :data:`METHODS` or ``"all"`` (one batch of each in turn). ``setting``: limits and
    simulation settings (default: :class:`Setting` with ``seed``). ``on_batch`` is called after every batch (with
    ``workers > 1``: with the merged report so far). ``workers``: parallel streams, each with its share of
    ``scenarios`` (a count of processes, or a :class:`~safelane.parallel.Backend`); ``stream``: this run's stream
    number.
    """
    methods = METHODS if method == "all" else (method,)
    if any(m not in METHODS for m in methods):
        raise ValueError(f"method must be one of {(*METHODS, 'all')}; got {method!r}")
    backend = workers if isinstance(workers, Backend) else None
    if scenarios < 0 or minutes < 0 or batch_size < 1 or (backend is None and workers < 1):
        raise ValueError("scenarios and minutes must be >= 0, batch_size and workers >= 1")
    setting = setting or Setting(seed=seed)
    setting = dataclasses.replace(setting, seed=seed).resolved()
    backend = backend or as_backend(workers)
    if not backend.in_process:
        return _parallel(scenarios, minutes, seed, method, batch_size, setting, on_batch, backend)
    prm = setting.params
    dim = space.dimension(prm, setting.world)
    report = Report(seed=seed, methods=methods, hooks=setting.use_hooks, profiles=setting.use_profiles)
    cem = CrossEntropy(dim)
    start = time.perf_counter()
    index = 0
    while report.simulated < scenarios or time.perf_counter() - start < 60.0 * minutes:
        # One round: every method's batch drawn first (none depends on another's outcome this round: the
        # cross-entropy search reads the outcomes of its own previous batch), then simulated as one batch (the
        # scenarios are independent: the same rows, the same bits; fewer, larger calls of the simulator).
        drawn = []
        for m in methods:
            rng = np.random.default_rng([seed, stream, METHODS.index(m), index])
            # Without profiles, L(N+1)'s sudden braking starts at one instant per batch (period-aligned or not).
            brake_start = (
                0.0
                if report.profiles
                else float(rng.choice([0.0, rng.integers(0, 30) * prm.dt, rng.uniform(0.0, 3.0)]))
            )
            if m == "knife":
                spec, u = space.knife_specs(rng, batch_size, prm, brake_start, setting.world), None
            else:
                u = cem.ask(rng, batch_size) if m == "cem" else rng.uniform(size=(batch_size, dim))
                spec = space.decode(u, prm, brake_start, setting.world)
            drawn.append((m, spec, u))
        outcomes, kept_rows = evaluate_round([spec for _, spec, _ in drawn], setting)
        for (m, _, u), outcome, kept in zip(drawn, outcomes, kept_rows, strict=True):
            if m == "cem":
                scores = np.full(batch_size, np.inf)
                scores[outcome["row"].to_numpy()] = score(outcome)
                cem.tell(u, scores)
            report.add(m, batch_size, outcome.reset_index(drop=True), kept, setting)
            report.wall_s = time.perf_counter() - start
            if on_batch is not None:
                on_batch(report)
        index += 1
    return report


def _stream(args, progress) -> Report:
    """One stream of a parallel run (a job of :func:`~safelane.parallel.map_chunks`); progress goes to the channel."""
    scenarios, minutes, seed, method, batch_size, setting, stream = args

    def report_progress(report: Report) -> None:
        progress.put((stream, report.summary(), report.min_ratio))

    return falsify(scenarios, minutes, seed, method, batch_size=batch_size, setting=setting, stream=stream,
                   on_batch=report_progress)  # fmt: skip


def _parallel(scenarios, minutes, seed, method, batch_size, setting, on_batch, backend: Backend) -> Report:
    """``backend.parallelism()`` streams on the backend (processes, or Ray tasks); progress comes back through a
    channel (a ``multiprocessing.Manager`` queue, or a Ray queue actor) as each stream finishes a batch.

    Every stream runs until its share of ``scenarios`` and ``minutes`` are reached. On Ray a stream waits for a free
    CPU: with more streams than the cluster has CPUs, the time box applies to each stream, so the run takes
    ``minutes`` times the number of rounds of streams the cluster can hold at once."""
    workers = backend.parallelism()
    share = -(-scenarios // workers)
    jobs = [(share, minutes, seed, method, batch_size, setting, w) for w in range(workers)]
    latest: dict[int, tuple] = {}

    def on_progress(message) -> None:
        stream, summary, min_ratio = message
        latest[stream] = (summary, min_ratio)
        if on_batch is None:
            return
        partial = Report(seed=seed, methods=(), hooks=False, profiles=False)
        partial.simulated = sum(v[0]["scenarios_simulated"] for v in latest.values())
        partial.min_ratio = min(v[1] for v in latest.values())
        partial.counts = {
            "collision": sum(v[0]["collisions"] for v in latest.values()),
            "safety_violation": sum(v[0]["p_m_violations_ego"] for v in latest.values()),
            "leader_collision": sum(v[0]["leader_collisions"] for v in latest.values()),
            "leader_violation": sum(v[0]["p_m_violations_leaders"] for v in latest.values()),
            "assumption_breach": sum(v[0]["assumption_breaches_flagged"] for v in latest.values()),
            "n_invalid_proposals": sum(v[0]["invalid_proposals"] for v in latest.values()),
        }
        on_batch(partial)

    return merge(map_chunks(_stream, jobs, backend, progress=on_progress))
