"""Train the neural planners: sample states → teacher labels → fit → DAgger rounds → export → evaluate.

A run is described completely by a :class:`TrainConfig` (YAML ↔ config 1:1, unknown keys are errors; see
``safelane/models/default_train.yaml``); its SHA-256 (:meth:`TrainConfig.config_hash`) is stored in the model.
Same config → same weights: NumPy randomness comes from ``numpy.random.default_rng(seed)`` streams, the weight
initialisation from an explicit ``torch.Generator`` seeded with ``seed``; training runs on ``threads`` CPU threads.

Loss: mean squared error of the actions divided by each head's half range (``a_x`` and ``a_y`` errors weigh
alike). Adam, learning rate halved on validation plateaus, early stopping on the validation loss (best weights
restored). Files written to ``out_dir``: ``model.npz`` (+ ``model.onnx``), ``model.json`` (the model's metadata,
training summary and closed-loop results: a machine-readable model card), ``metrics.csv`` (one row per epoch),
``summary.json``, ``config.yaml`` and, when evaluation cells are configured, ``closed_loop.csv``.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd
import yaml
from pydantic import BaseModel, ConfigDict, Field

from .. import __version__
from ..config import load_model
from ..params import Params
from ..planners.base import ExpertPlanner
from ..planners.nn import HEADS, MLPPlanner, head_bounds
from ..planners.teacher import OptimalControlTeacher, TeacherConfig
from ..sim.preset import load_preset
from .closed_loop import DaggerConfig, EvalConfig, collect_states, evaluate_closed_loop
from .data import DataConfig, label, sample_observations

_FROZEN = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class ModelConfig(BaseModel):
    """Architecture of each of the two networks."""

    model_config = _FROZEN
    hidden: tuple[int, ...] = Field((64, 64), min_length=1, description="Hidden-layer widths.")
    activation: Literal["tanh", "relu"] = Field("tanh", description="Hidden activation.")


class OptimConfig(BaseModel):
    """Optimiser, split and early stopping."""

    model_config = _FROZEN
    lr: float = Field(3e-3, gt=0.0, description="Adam learning rate.")
    weight_decay: float = Field(0.0, ge=0.0, description="Adam weight decay.")
    batch_size: int = Field(512, ge=1, description="Mini-batch size.")
    max_epochs: int = Field(150, ge=1, description="Maximum epochs of the initial fit.")
    patience: int = Field(15, ge=1, description="Epochs without validation improvement before stopping.")
    val_fraction: float = Field(0.1, gt=0.0, lt=1.0, description="Share of states held out for validation.")


class TrainConfig(BaseModel):
    """Everything that defines a training run."""

    model_config = _FROZEN
    seed: int = Field(0, ge=0, description="Seed of every random stream of the run.")
    threads: int = Field(1, ge=1, description="PyTorch CPU threads.")
    params: Params = Field(default_factory=Params, description="Mechanical limits and geometry.")
    data: DataConfig = Field(default_factory=DataConfig)
    teacher: TeacherConfig = Field(default_factory=TeacherConfig)
    teacher_preset: str | None = Field(
        None,
        description="Distil this preset's calibrated nominal planner (and use its params) instead of the "
        "optimal-control teacher (the NN planner of the paper-faithful Table 1, docs/reproduction.md).",
    )
    model: ModelConfig = Field(default_factory=ModelConfig)
    optim: OptimConfig = Field(default_factory=OptimConfig)
    dagger: DaggerConfig = Field(default_factory=DaggerConfig)
    evaluation: EvalConfig = Field(default_factory=EvalConfig)
    export_onnx: bool = Field(True, description="Also write model.onnx (needs the onnx package).")

    def config_hash(self) -> str:
        """SHA-256 of the canonical JSON of the config."""
        blob = json.dumps(self.model_dump(mode="json"), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()

    @classmethod
    def load(cls, path: Path | str | None) -> TrainConfig:
        """From a YAML/JSON file (defaults when ``path`` is None)."""
        return load_model(cls, path)


@dataclass
class TrainResult:
    """What :func:`train` produced."""

    planner: MLPPlanner
    summary: dict
    metrics: pd.DataFrame
    out_dir: Path


def _progress(enabled: bool):
    """Progress bars on stderr: stdout stays for the result (``safelane train`` prints its JSON summary there)."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    cols = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            TextColumn("{task.fields[info]}"))
    return Progress(*cols, console=Console(stderr=True), disable=not enabled, transient=False)


def _stage_printer(progress: bool, t_start: float):
    """Without progress bars, one line per stage on stderr (with the elapsed time), so a long run is not silent."""
    import sys

    def say(message: str) -> None:
        if not progress:
            print(f"[train {time.perf_counter() - t_start:6.1f} s] {message}", file=sys.stderr, flush=True)

    return say


def _fit(module, torch, data, cfg: TrainConfig, max_epochs: int, rng, progress, round_no: int, log: list) -> None:
    """Adam with early stopping on ``data = (x_tr, y_tr, x_va, y_va)`` tensors; restores the best weights."""
    x_tr, y_tr, x_va, y_va = data
    scale = module.out_half
    opt = torch.optim.Adam(module.parameters(), lr=cfg.optim.lr, weight_decay=cfg.optim.weight_decay)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=max(cfg.optim.patience // 3, 1))
    best, best_state, stale = np.inf, None, 0
    task = progress.add_task(f"round {round_no} epochs", total=max_epochs, info="")
    n, bs = len(x_tr), cfg.optim.batch_size
    for epoch in range(max_epochs):
        t0 = time.perf_counter()
        module.train()
        perm = torch.from_numpy(rng.permutation(n))
        total = 0.0
        for s in range(0, n, bs):
            idx = perm[s : s + bs]
            loss = (((module(x_tr[idx]) - y_tr[idx]) / scale) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
        module.eval()
        with torch.no_grad():
            err = module(x_va) - y_va
            val = float(((err / scale) ** 2).mean())
            rmse = torch.sqrt((err**2).mean(0)).tolist()
        sched.step(val)
        log.append({"round": round_no, "epoch": epoch, "train_loss": total / n, "val_loss": val,
                    **{f"val_rmse_{h}": r for h, r in zip(HEADS, rmse, strict=True)},
                    "lr": opt.param_groups[0]["lr"], "seconds": time.perf_counter() - t0})
        progress.update(task, advance=1, info=f"val {val:.2e}")
        if val < best - 1e-9:
            best, stale = val, 0
            best_state = {k: v.detach().clone() for k, v in module.state_dict().items()}
        else:
            stale += 1
            if stale >= cfg.optim.patience:
                break
    progress.update(task, total=epoch + 1, completed=epoch + 1)
    module.load_state_dict(best_state)


def train(cfg: TrainConfig, out_dir: Path | str, progress: bool = True) -> TrainResult:
    """Run the whole pipeline of the module docstring; returns the planner and writes the files to ``out_dir``.

    Deterministic: PyTorch runs with ``torch.use_deterministic_algorithms(True)`` on ``cfg.threads`` threads and
    NumPy's BLAS on as many (restored afterwards), so the same config on the same software gives the same
    weights bit for bit."""
    from threadpoolctl import threadpool_limits

    from .torch_model import require_torch

    torch = require_torch()
    previous = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True)
    try:
        with threadpool_limits(limits=cfg.threads, user_api="blas"):
            return _train(torch, cfg, out_dir, progress)
    finally:
        torch.use_deterministic_algorithms(previous)


def _train(torch, cfg: TrainConfig, out_dir: Path | str, progress: bool) -> TrainResult:
    from .torch_model import TorchPlanner, init_weights, to_planner

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg.threads)
    prm, teacher = cfg.params, OptimalControlTeacher(cfg.teacher)
    provenance = {}
    if cfg.teacher_preset:
        preset = load_preset(cfg.teacher_preset)
        prm, teacher = preset.params, preset.expert()
        # What the network imitates, so that a stale network is detectable (tests compare it with the preset).
        provenance["teacher_preset"] = {"name": preset.name, "params": prm.model_dump(),
                                        "planner": dict(preset.planner)}  # fmt: skip
    rng = np.random.default_rng(cfg.seed)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    log: list[dict] = []

    def labelled(obs):
        t0 = time.perf_counter()
        x, y = label(obs, prm, teacher)
        timings["labelling_s"] = timings.get("labelling_s", 0.0) + time.perf_counter() - t0
        is_val = rng.random(len(x)) < cfg.optim.val_fraction
        return x[~is_val], y[~is_val], x[is_val], y[is_val]

    def as_tensors(parts):
        return tuple(torch.from_numpy(np.asarray(a, np.float32)) for a in parts)

    say = _stage_printer(progress, t_start)
    with _progress(progress) as bar:
        task = bar.add_task("labelling states", total=1, info=f"{cfg.data.n_states} states")
        say(f"labelling {cfg.data.n_states} teacher states")
        parts = labelled(sample_observations(cfg.data.n_states, rng, prm, cfg.data))
        bar.update(task, completed=1, info=f"{timings['labelling_s']:.1f} s")
        say(f"fitting round 0 (up to {cfg.optim.max_epochs} epochs)")
        mean = parts[0].mean(axis=0)
        std = parts[0].std(axis=0)
        std = np.where(std > 1e-8, std, 1.0)  # a constant feature (e.g. no connected followers) passes through
        module = TorchPlanner(mean, std, cfg.model.hidden, cfg.model.activation, head_bounds(prm))
        init_weights(module, torch.Generator().manual_seed(cfg.seed))  # explicit generator, no global seeding
        t0 = time.perf_counter()
        _fit(module, torch, as_tensors(parts), cfg, cfg.optim.max_epochs, rng, bar, 0, log)
        timings["fit_s"] = time.perf_counter() - t0
        for r in range(1, cfg.dagger.rounds + 1):
            say(f"DAgger round {r}/{cfg.dagger.rounds}: simulating, labelling and fitting")
            t0 = time.perf_counter()
            visited = collect_states(to_planner(module), cfg.dagger, prm, rng, seed=cfg.seed * 1000 + r * 100)
            timings["dagger_sim_s"] = timings.get("dagger_sim_s", 0.0) + time.perf_counter() - t0
            new = labelled(visited)
            parts = tuple(np.concatenate([a, b]) for a, b in zip(parts, new, strict=True))
            t0 = time.perf_counter()
            _fit(module, torch, as_tensors(parts), cfg, cfg.dagger.epochs_per_round, rng, bar, r, log)
            timings["fit_s"] += time.perf_counter() - t0
    # A fresh test set from the paper component alone: the error where the experiments happen.
    x_test, y_test = label(sample_observations(max(cfg.data.n_states // 20, 100), rng, prm,
                                               cfg.data.model_copy(update={"paper_fraction": 1.0})), prm, teacher)
    test_rmse = np.sqrt(((to_planner(module).predict(x_test) - y_test) ** 2).mean(axis=0))
    metrics = pd.DataFrame(log)
    last = metrics[metrics["round"] == metrics["round"].max()]
    best = last.loc[last["val_loss"].idxmin()]  # the weights restored by early stopping
    timings["total_s"] = time.perf_counter() - t_start
    summary = {
        "safelane_version": __version__,
        "train_config_hash": cfg.config_hash(),
        "n_train": len(parts[0]),
        "n_val": len(parts[2]),
        "val_loss": float(best["val_loss"]),
        **{f"val_rmse_{h}_mps2": float(best[f"val_rmse_{h}"]) for h in HEADS},
        **{f"test_paper_rmse_{h}_mps2": float(r) for h, r in zip(HEADS, test_rmse, strict=True)},
        "n_test_paper": len(x_test),
        "epochs": len(metrics),
        "timings_s": {k: round(v, 2) for k, v in timings.items()},
    }
    planner = to_planner(module, {"safelane_version": __version__, "train_config_hash": cfg.config_hash(),
                                  "train_config": cfg.model_dump(mode="json"), "training": summary, **provenance})
    planner.save(out_dir / "model.npz")
    if cfg.export_onnx:
        planner.to_onnx(out_dir / "model.onnx")
    metrics.to_csv(out_dir / "metrics.csv", index=False)
    (out_dir / "config.yaml").write_text(yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False))
    ev = cfg.evaluation
    if ev.cells:
        say(f"closed-loop evaluation: {len(ev.cells)} cells x {ev.samples} scenarios")
        baselines = {"expert": ExpertPlanner(), "teacher": teacher}
        candidates = {"mlp": planner, **{b: baselines[b] for b in ev.baselines}}
        t0 = time.perf_counter()
        table = evaluate_closed_loop(candidates, ev.cells, ev.samples, ev.seed, prm)
        table.to_csv(out_dir / "closed_loop.csv", index=False)
        summary["timings_s"]["evaluation_s"] = round(time.perf_counter() - t0, 2)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    card = {**planner.full_metadata(), "closed_loop": json.loads(table.to_json(orient="records")) if ev.cells else []}
    (out_dir / "model.json").write_text(json.dumps(card, indent=2))
    say("done")
    return TrainResult(planner=planner, summary=summary, metrics=metrics, out_dir=out_dir)
