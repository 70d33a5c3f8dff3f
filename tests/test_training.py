"""Teacher, training data, `safelane train`, determinism, DAgger state collection."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from safelane import Params
from safelane.planners.base import Observation
from safelane.planners.nn import MLPPlanner
from safelane.planners.teacher import OptimalControlTeacher, TeacherConfig
from safelane.training.data import DataConfig, concat_observations, sample_observations, take

PARAMS = Params()
FAST_TEACHER = {"n_candidates": 16, "n_iters": 2, "n_refine": 2}


def tiny_config(seed: int = 0, **extra) -> dict:
    """A training run of about a second: 1,500 states, a cheap teacher, 16-wide networks, 4 epochs."""
    return {
        "seed": seed,
        "data": {"n_states": 1500},
        "teacher": FAST_TEACHER,
        "model": {"hidden": [16, 16]},
        "optim": {"max_epochs": 4, "batch_size": 256},
        **extra,
    }


def merge_scene(gap_l: float, gap_f: float, v_f: float = 30.0, b: int = 1) -> Observation:
    """Ego at 30 m/s starting a lane change, ``L1`` ``gap_l`` ahead at 30 m/s, non-connected ``F`` ``gap_f`` behind."""
    z = np.zeros(b)
    return Observation(p_x=z, p_y=z, v_x=z + 30.0, v_y=z, p_x_l=z + gap_l, v_x_l=z + 30.0, p_x_f=z - gap_f,
                       v_x_f=z + v_f, l1_plan=np.zeros((b, 10)), l1_connected=z > 0, f_connected=z > 0,
                       completed=z > 0)


def rollout(planner, obs: Observation, seconds: float) -> np.ndarray:
    """Lateral positions ``(steps, B)`` with the ego driven by ``planner``, neighbours at constant speed."""
    dt, ys = PARAMS.dt, []
    for _ in range(round(seconds / dt)):
        a_x, a_y = planner(obs, PARAMS)
        obs = replace(
            obs, p_x=obs.p_x + obs.v_x * dt + 0.5 * a_x * dt**2, v_x=obs.v_x + a_x * dt,
            p_y=obs.p_y + obs.v_y * dt + 0.5 * a_y * dt**2, v_y=obs.v_y + a_y * dt,
            p_x_l=obs.p_x_l + obs.v_x_l * dt, p_x_f=obs.p_x_f + obs.v_x_f * dt,
        )
        ys.append(obs.p_y)
    return np.array(ys)


# ---------------------------------------------------------------- teacher
def test_teacher_merges_into_an_open_gap_quickly():
    ys = rollout(OptimalControlTeacher(), merge_scene(20.0, 20.0), 4.0)
    crossing_s = (np.argmax(ys[:, 0] > PARAMS.y_boundary) + 1) * PARAMS.dt
    assert ys[:, 0].max() > PARAMS.y_boundary and crossing_s < 2.2  # the hand rule needs 2.6 s
    assert abs(ys[-1, 0] - PARAMS.lane_width) < 0.3


def test_teacher_waits_when_a_fast_follower_is_alongside():
    ys = rollout(OptimalControlTeacher(), merge_scene(15.0, 3.0, v_f=33.0), 3.0)
    overlap = PARAMS.lane_width - PARAMS.vehicle_width
    assert ys.max() < overlap + 0.05  # never more than grazes the target lane


def test_teacher_labels_are_deterministic_and_batch_invariant():
    obs = sample_observations(300, np.random.default_rng(0), PARAMS, DataConfig())
    teacher = OptimalControlTeacher(TeacherConfig(chunk_size=64))
    a = np.stack(teacher(obs, PARAMS))
    idx = np.arange(40, 90)
    b = np.stack(OptimalControlTeacher()(take(obs, idx), PARAMS))
    np.testing.assert_allclose(a[:, idx], b, atol=1e-6)
    assert np.all(a[0] >= -PARAMS.a_x_d) and np.all(a[0] <= PARAMS.a_x_a) and np.all(np.abs(a[1]) <= PARAMS.a_y_m)


def test_teacher_gradient_matches_finite_differences():
    teacher = OptimalControlTeacher()
    captured = {}
    original = teacher._refine

    def spy(u, ctx, prm, t, lo, hi):
        captured.update(u=u, ctx=ctx, t=t)
        return original(u, ctx, prm, t, lo, hi)

    teacher._refine = spy
    teacher(sample_observations(40, np.random.default_rng(5), PARAMS, DataConfig()), PARAMS)
    ctx = {k: np.asarray(v, np.float64) for k, v in captured["ctx"].items()}
    u = captured["u"].astype(np.float64) + np.random.default_rng(6).normal(0.0, 0.3, captured["u"].shape)
    _, grad, _, _ = teacher._cost(u[:, None], ctx, PARAMS, captured["t"], grad=True)
    num = np.empty_like(u)
    for i in range(u.shape[1]):
        e = np.zeros(u.shape[1])
        e[i] = 1e-6
        hi, lo = (teacher._cost((u + s * e)[:, None], ctx, PARAMS, captured["t"])[:, 0] for s in (1, -1))
        num[:, i] = (hi - lo) / 2e-6
    np.testing.assert_allclose(grad[:, 0], num, rtol=1e-4, atol=1e-3)


def test_teacher_config_rejects_bad_knots():
    with pytest.raises(ValidationError, match="must start at 0"):
        TeacherConfig(knot_times_s=(0.5, 1.0))
    with pytest.raises(ValidationError, match="beyond horizon"):
        TeacherConfig(knot_times_s=(0.0, 5.0))


# ---------------------------------------------------------------- data
def test_sampler_is_seeded_and_covers_the_paper_distribution():
    a = sample_observations(4000, np.random.default_rng(7), PARAMS, DataConfig())
    b = sample_observations(4000, np.random.default_rng(7), PARAMS, DataConfig())
    np.testing.assert_array_equal(a.v_x, b.v_x)
    np.testing.assert_array_equal(a.l1_plan, b.l1_plan)
    gap = a.p_x_l - a.p_x
    assert ((gap > 17) & (gap < 22) & (a.v_x > 29) & (a.v_x < 31) & (a.p_y == 0)).sum() > 100
    assert gap.max() > 50 and a.v_x.min() < 10 and a.l1_plan.min() < -5.0  # and well beyond
    assert np.all(a.l1_plan[~a.l1_connected] == 0.0)
    both = concat_observations([take(a, slice(0, 10)), take(b, slice(0, 5))])
    assert both.p_x.shape == (15,) and both.l1_plan.shape == (15, a.l1_plan.shape[1])


# ---------------------------------------------------------------- training
def test_config_yaml_round_trip_and_unknown_keys(tmp_path):
    from safelane.training.train import TrainConfig

    cfg = TrainConfig.model_validate(tiny_config())
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(cfg.model_dump(mode="json")))
    again = TrainConfig.load(path)
    assert again == cfg and again.config_hash() == cfg.config_hash()
    path.write_text(yaml.safe_dump({**tiny_config(), "optim": {"max_epochs": 2, "learning_rate": 1.0}}))
    with pytest.raises(ValueError, match="learning_rate"):
        TrainConfig.load(path)


def test_cli_train_tiny_config(tmp_path):
    pytest.importorskip("torch")
    from typer.testing import CliRunner

    from safelane.cli import app

    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump(tiny_config()))
    result = CliRunner().invoke(app, ["train", "--config", str(cfg), "--out", str(tmp_path / "out"), "--no-progress"])
    assert result.exit_code == 0, result.output
    assert "labelling" in result.output and "done" in result.output  # --no-progress: one line per stage
    (out,) = (tmp_path / "out").iterdir()  # the run folder
    assert json.loads((out / "run.json").read_text())["status"] == "complete"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["epochs"] >= 1 and np.isfinite(summary["val_loss"])
    planner = MLPPlanner.load(out / "model.npz")
    assert planner.metadata["train_config_hash"] == summary["train_config_hash"]
    a_x, a_y = planner(sample_observations(500, np.random.default_rng(1), PARAMS, DataConfig()), PARAMS)
    assert np.all((-PARAMS.a_x_d <= a_x) & (a_x <= PARAMS.a_x_a)) and np.all(np.abs(a_y) <= PARAMS.a_y_m)
    assert (out / "metrics.csv").read_text().startswith("round,epoch,train_loss,val_loss")
    bad = tmp_path / "bad.yaml"
    bad.write_text("seed: 0\nbogus: 1\n")
    result = CliRunner().invoke(app, ["train", "--config", str(bad), "--out", str(tmp_path / "out")])
    assert result.exit_code != 0 and "bogus" in result.output


def test_same_seed_same_weights(tmp_path):
    pytest.importorskip("torch")
    from safelane.training.train import TrainConfig, train

    runs = [
        train(TrainConfig.model_validate(tiny_config(seed)), tmp_path / f"r{k}", progress=False).planner
        for k, seed in enumerate((4, 4, 5))
    ]
    for (w0, b0), (w1, b1) in zip(runs[0].layers["a_y"], runs[1].layers["a_y"], strict=True):
        np.testing.assert_array_equal(w0, w1)
        np.testing.assert_array_equal(b0, b1)
    assert not np.array_equal(runs[0].layers["a_x"][0][0], runs[2].layers["a_x"][0][0])


def test_dagger_round_collects_visited_states(tmp_path):
    pytest.importorskip("torch")
    from safelane.training.train import TrainConfig, train

    dagger = {"rounds": 1, "cells": [{"variant": "CV_all", "n_leaders": 1, "decel": 4.0}],
              "scenarios_per_cell": 8, "states_per_round": 100, "epochs_per_round": 2, "horizon_s": 2.0}
    cfg = TrainConfig.model_validate(tiny_config(dagger=dagger, export_onnx=False))
    result = train(cfg, tmp_path, progress=False)
    assert set(result.metrics["round"]) == {0, 1}
    assert result.summary["n_train"] + result.summary["n_val"] == 1500 + 100  # 8 scenarios x 20 steps visited, 100 kept
    assert not (tmp_path / "model.onnx").exists()


def test_weight_init_uses_an_explicit_generator():
    torch = pytest.importorskip("torch")
    from safelane.training.torch_model import TorchPlanner, init_weights

    args = (np.zeros(12), np.ones(12), (16, 16), "tanh", {"a_x": (-8.0, 2.5), "a_y": (-1.5, 1.5)})
    module = TorchPlanner(*args)
    before = torch.get_rng_state()
    init_weights(module, torch.Generator().manual_seed(3))
    assert torch.equal(before, torch.get_rng_state())  # the global generator is untouched
    with torch.random.fork_rng(devices=[]):  # the same draws nn.Linear makes from a seeded global generator
        torch.manual_seed(3)
        reference = TorchPlanner(*args)
    for got, want in zip(module.state_dict().values(), reference.state_dict().values(), strict=True):
        assert torch.equal(got, want)
