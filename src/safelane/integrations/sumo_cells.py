"""Experiment cells in SUMO, comparable with the built-in simulator: the same sampled scenarios, planner variant,
nominal planner and shield settings as ``safelane simulate``; episodes spread over processes (one libsumo each).

    from safelane.integrations.sumo_cells import cell_scenarios, run_episodes
    batch, scenarios = cell_scenarios("CV_all", n_leaders=3, decel=4.0, episodes=50, seed=0)
    results = run_episodes(scenarios, planner="CV_all", traffic="paper", workers=2)   # EpisodeResult, in order

``cell_scenarios`` draws the cell's initial states exactly as :func:`safelane.sim.simulate` does
(:func:`~safelane.sim.inputs.cell_rng` and :func:`~safelane.sim.scenario.paper_scenarios`): ``batch`` run by
:func:`safelane.sim.simulate_batch` and ``scenarios`` run in SUMO are the same lane changes.
"""

from __future__ import annotations

import multiprocessing as mp
from pathlib import Path

from ..params import Params
from .sumo import EpisodeResult, SumoRunner, SumoScenario, scenarios_from_batch

__all__ = ["cell_scenarios", "fcd_path", "run_episodes", "shield_config"]


def cell_scenarios(planner: str, n_leaders: int, decel: float, episodes: int, seed: int = 0, *, config=None):
    """``(ScenarioBatch, [SumoScenario])``: the cell's scenarios as ``safelane simulate`` samples them (the same
    seed gives the same initial states), L(N+1) braking from ``SimConfig.brake_start_s``."""
    from ..sim import SimConfig
    from ..sim.inputs import cell_rng, check_cell_args
    from ..sim.scenario import paper_scenarios

    check_cell_args(planner, n_leaders, decel, episodes, seed, 0.0)
    cfg = config or SimConfig()
    batch = paper_scenarios(planner, n_leaders, decel, episodes, cell_rng(seed, n_leaders, decel, 0.0))
    return batch, scenarios_from_batch(batch, brake_start_s=cfg.brake_start_s)


def shield_config(config=None):
    """The :class:`~safelane.shield.ShieldConfig` the built-in simulator gives the shield for a ``SimConfig``
    (``safelane.sim.step.ClosedLoop``; the paper's world: no delay, no own lane, exact sensing)."""
    from ..sim import SimConfig

    # The runner models no actuation delay of its own here: the shield accounts for none.
    return (config or SimConfig()).shield.model_copy(update={"actuation_delay_s": 0.0})


def fcd_path(fcd: str | Path | None, scenario_id: int, episodes: int) -> str | None:
    """Where an episode's floating-car data goes: ``fcd`` itself for a single episode, else the scenario id before
    the suffix (``out.xml`` → ``out-7.xml``)."""
    if fcd is None:
        return None
    fcd = Path(fcd)
    return str(fcd if episodes == 1 else fcd.with_name(f"{fcd.stem}-{scenario_id}{fcd.suffix}"))


# -- one SUMO per process -------------------------------------------------------------------------------------------
_RUNNER: SumoRunner | None = None
_SETTINGS: dict = {}


def _runner_kwargs(planner: str, traffic: str, seed: int, params: Params | None, gui: bool, nominal=None) -> dict:
    """The :class:`SumoRunner` of a cell; its policy is :func:`~.sumo.default_policy` of ``planner`` and
    ``nominal`` (a name or model path travels to worker processes as such, each loads it)."""
    from ..sim import SimConfig

    cfg = SimConfig()
    return dict(params=params, variant=planner, config=shield_config(cfg), traffic=traffic, seed=seed,
                horizon_s=cfg.horizon_s, v2x_max_age_s=cfg.v2x_max_age_s, gui=gui, nominal=nominal)  # fmt: skip


def _init_worker(kwargs: dict) -> None:
    global _RUNNER
    _RUNNER = SumoRunner(**kwargs)


def _run_one(job) -> EpisodeResult:
    sc, shielded, fcd = job
    world = _RUNNER.world
    world.fcd = fcd
    return _RUNNER.run(sc, shielded=shielded)


def run_episodes(
    scenarios: list[SumoScenario],
    *,
    planner: str = "CV_all",
    traffic: str = "paper",
    seed: int = 0,
    shielded: bool = True,
    workers: int = 1,
    params: Params | None = None,
    gui: bool = False,
    fcd: str | Path | None = None,
    nominal=None,
    progress: bool = False,
) -> list[EpisodeResult]:
    """Run ``scenarios`` in SUMO with the built-in simulator's nominal planner (``nominal``: a planner, a registered
    name or a ``.npz``/``.onnx`` model path; default :data:`~.sumo.DEFAULT_NOMINAL`, as ``SumoRunner()``), shield
    settings and horizon; results in the order of ``scenarios``.

    ``workers > 1`` spreads the episodes over that many spawned processes, each with its own SUMO (libsumo allows
    one simulation per process); ``workers == 1`` runs them in this process (which must not hold an open SUMO).
    ``gui`` (sumo-gui through TraCI) runs in this process only."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1; got {workers}")
    if gui and workers > 1:
        raise ValueError("gui runs in one process: use workers = 1")
    kwargs = _runner_kwargs(planner, traffic, seed, params, gui, nominal)
    jobs = [(sc, shielded, fcd_path(fcd, sc.scenario_id, len(scenarios))) for sc in scenarios]
    workers = min(workers, max(len(jobs), 1))
    if workers == 1:
        with SumoRunner(**kwargs) as runner:
            out = []
            for sc, sh, path in _track(jobs, progress, len(jobs)):
                runner.world.fcd = path
                out.append(runner.run(sc, shielded=sh))
        return out
    ctx = mp.get_context("spawn")  # a fresh interpreter per worker: one libsumo each
    with ctx.Pool(workers, initializer=_init_worker, initargs=(kwargs,)) as pool:
        done = list(_track(pool.imap(_run_one, jobs, chunksize=1), progress, len(jobs)))
    return done


def _track(items, progress: bool, total: int):
    if not progress:
        return items
    from .._progress import track

    return track(items, f"SUMO: {total} episodes", total=total)
