"""Neural planner: feature map, NumPy forward pass vs PyTorch / ONNX Runtime, the checked .npz format."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from safelane import Params
from safelane.planners.base import NominalPlanner, Observation
from safelane.planners.features import FEATURE_NAMES, features, plan_speed_change
from safelane.planners.nn import HEADS, MLPPlanner, head_bounds, load_default_planner
from safelane.training.data import DataConfig, sample_observations

PARAMS = Params()
N_PARITY = 10_000
TOL = 1e-5  # m/s², float32 forward passes


def random_planner(seed: int = 0, hidden=(32, 32), activation: str = "tanh") -> MLPPlanner:
    """A planner with random (but well-scaled) weights, so outputs spread over the whole action range."""
    rng = np.random.default_rng(seed)
    widths = (len(FEATURE_NAMES), *hidden, 1)
    layers = {
        h: tuple(
            (
                (rng.standard_normal((a, b)) * 1.5 / np.sqrt(a)).astype(np.float32),
                (0.1 * rng.standard_normal(b)).astype(np.float32),
            )
            for a, b in itertools.pairwise(widths)
        )
        for h in HEADS
    }
    mean = rng.normal(0.0, 5.0, len(FEATURE_NAMES))
    std = rng.uniform(0.5, 10.0, len(FEATURE_NAMES))
    return MLPPlanner(layers, mean, std, head_bounds(PARAMS), activation, {"note": "random"})


def random_features(n: int, seed: int = 1) -> np.ndarray:
    obs = sample_observations(n, np.random.default_rng(seed), PARAMS, DataConfig())
    return features(obs, PARAMS)


def open_gap_observation(b: int = 4) -> Observation:
    """Ego at the start of a lane change alongside a 20 m / 20 m gap, everyone at 30 m/s."""
    z = np.zeros(b)
    return Observation(p_x=z + 100.0, p_y=z, v_x=z + 30.0, v_y=z, p_x_l=z + 120.0, v_x_l=z + 30.0,
                       p_x_f=z + 80.0, v_x_f=z + 30.0, l1_plan=np.zeros((b, 10)), l1_connected=z > 0,
                       f_connected=z > 0, completed=z > 0)


# ---------------------------------------------------------------- features
def test_features_shape_and_names():
    obs = sample_observations(37, np.random.default_rng(0), PARAMS, DataConfig())
    x = features(obs, PARAMS)
    assert x.shape == (37, len(FEATURE_NAMES)) and np.all(np.isfinite(x))


def test_features_are_shift_invariant():
    obs = open_gap_observation()
    shifted = Observation(**{**obs.__dict__, "p_x": obs.p_x + 1e3, "p_x_l": obs.p_x_l + 1e3, "p_x_f": obs.p_x_f + 1e3})
    np.testing.assert_allclose(features(shifted, PARAMS), features(obs, PARAMS), atol=1e-9)


def test_features_golden_open_gap():
    x = dict(zip(FEATURE_NAMES, features(open_gap_observation(1), PARAMS)[0], strict=True))
    assert x["gap_l"] == 20.0 and x["gap_f"] == 20.0 and x["dv_l"] == 0.0 and x["v_x"] == 30.0
    assert x["l1_dv_1s"] == 0.0 and x["f_connected"] == 0.0


def test_plan_speed_change_hand_computed():
    plan = np.array([[-2.0] * 15, [1.0] * 15])  # 1.5 s of plan at dt = 0.1
    out = plan_speed_change(plan, np.array([1.5, 20.0]), 0.1)
    # Braking at 2 m/s² from 1.5 m/s stops after 0.75 s; accelerating stops changing after the plan ends.
    np.testing.assert_allclose(out, [[-1.5, -1.5, -1.5, -1.5], [1.0, 1.5, 1.5, 1.5]])
    assert np.all(plan_speed_change(np.zeros((3, 0)), np.ones(3), 0.1) == 0.0)


@pytest.mark.parametrize("horizon", [1, 3, 10, 25])
def test_plan_speed_change_is_the_running_sum_bit_for_bit(horizon):
    # Horizons of 0, 1, 4, 10 and 20 periods at dt = 0.1 (some past a short plan, two the same) on random plans: the
    # change is the sequential running sum's (a plain loop here, np.cumsum's order), floored, to the last bit.
    rng = np.random.default_rng(horizon)
    plan, v0 = rng.uniform(-9.0, 4.0, (500, horizon)), rng.uniform(0.0, 40.0, 500)
    times = (0.04, 0.1, 0.35, 1.0, 1.0, 2.0)
    running, expected = np.zeros(500), np.zeros((500, len(times)))
    for k in range(horizon):
        running = running + plan[:, k] if k else plan[:, 0].copy()
        for j, t in enumerate(times):
            if min(round(t / 0.1), horizon) == k + 1:
                expected[:, j] = np.maximum(0.1 * running, -v0)
    out = plan_speed_change(plan, v0, 0.1, times)
    assert out.tobytes() == expected.tobytes()


# ---------------------------------------------------------------- NumPy forward pass
@pytest.mark.parametrize("activation", ["tanh", "relu"])
def test_outputs_bounded_and_protocol(activation):
    planner = random_planner(activation=activation)
    assert isinstance(planner, NominalPlanner)
    x = random_features(2000) * 50.0  # far outside the training range
    out = planner.predict(x)
    for j, h in enumerate(HEADS):
        lo, hi = head_bounds(PARAMS)[h]
        assert lo <= out[:, j].min() and out[:, j].max() <= hi
    tight = Params(a_x_a=1.0, a_x_d=2.0, a_y_m=0.5)
    a_x, a_y = planner(sample_observations(500, np.random.default_rng(2), PARAMS, DataConfig()), tight)
    assert a_x.shape == a_y.shape == (500,)
    assert a_x.min() >= -2.0 and a_x.max() <= 1.0 and np.abs(a_y).max() <= 0.5


def test_numpy_matches_pytorch():
    pytest.importorskip("torch")
    import torch

    from safelane.training.torch_model import from_planner, to_planner

    planner = random_planner()
    x = random_features(N_PARITY)
    module = from_planner(planner)
    with torch.no_grad():
        ref = module(torch.from_numpy(x.astype(np.float32))).numpy()
    np.testing.assert_allclose(planner.predict(x), ref, rtol=0, atol=TOL)
    back = to_planner(module)
    np.testing.assert_array_equal(back.predict(x), planner.predict(x))


def test_numpy_matches_onnxruntime(tmp_path):
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    planner = random_planner()
    path = planner.to_onnx(tmp_path / "m.onnx")
    onnx_planner = MLPPlanner.from_onnx(path)
    x = random_features(N_PARITY)
    np.testing.assert_allclose(planner.predict(x), onnx_planner.predict(x), rtol=0, atol=TOL)
    obs = open_gap_observation()
    np.testing.assert_allclose(np.stack(planner(obs, PARAMS)), np.stack(onnx_planner(obs, PARAMS)), atol=TOL)
    assert onnx_planner.metadata["feature_names"] == list(FEATURE_NAMES)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda m: m.update(features_version=0), "features v0"),
        (lambda m: m.update(format_version=99), "format version 99"),
        (lambda m: m.update(format="other"), "format is 'other'"),
    ],
)
def test_onnx_load_refuses_what_the_npz_load_refuses(tmp_path, edit, match):
    """The ONNX loader checks format, version and feature map as :meth:`MLPPlanner.load` does (same names under
    another feature meaning would otherwise load silently)."""
    onnx = pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    from safelane.planners.onnx_io import METADATA_KEY

    model = onnx.load(str(random_planner().to_onnx(tmp_path / "m.onnx")))
    (prop,) = [p for p in model.metadata_props if p.key == METADATA_KEY]
    meta = json.loads(prop.value)
    edit(meta)
    prop.value = json.dumps(meta)
    onnx.save(model, str(tmp_path / "edited.onnx"))
    with pytest.raises(ValueError, match=match):
        MLPPlanner.from_onnx(tmp_path / "edited.onnx")


# ---------------------------------------------------------------- persistence
def test_save_load_round_trip(tmp_path):
    planner = random_planner(activation="relu")
    loaded = MLPPlanner.load(planner.save(tmp_path / "m.npz"))
    x = random_features(1000)
    np.testing.assert_array_equal(loaded.predict(x), planner.predict(x))
    assert loaded.metadata["note"] == "random" and loaded.activation == "relu"
    assert loaded.metadata["feature_names"] == list(FEATURE_NAMES)


def _rewrite(src, dst, meta_edit=None, array_edit=None):
    with np.load(src) as npz:
        arrays = {k: npz[k] for k in npz.files}
    meta = json.loads(str(arrays.pop("metadata")))
    if meta_edit:
        meta_edit(meta)
    if array_edit:
        array_edit(arrays)
    np.savez(dst, metadata=np.array(json.dumps(meta)), **arrays)
    return dst


@pytest.mark.parametrize(
    ("meta_edit", "array_edit", "message"),
    [
        (lambda m: m.update(format_version=99), None, "format version 99"),
        (lambda m: m.update(feature_names=["p_x", *m["feature_names"][1:]]), None, "retrain the model"),
        (lambda m: m.update(features_version=0), None, "features v0"),
        (lambda m: m.update(safelane_version="99.0.0"), None, "newer than this safelane"),
        (lambda m: m.update(activation="gelu"), None, "unknown activation"),
        (lambda m: m["normalisation"].update(std=[0.0] * len(FEATURE_NAMES)), None, "std > 0"),
        (None, lambda a: a.update({"a_x/W1": a["a_x/W1"][:, :5]}), "metadata says"),
        (None, lambda a: a.pop("a_y/b0"), "missing weights"),
        (lambda m: m["heads"]["a_x"].update(layer_shapes=[[3, 32], [32, 32], [32, 1]]), None, "must start at"),
    ],
)
def test_mismatched_file_fails_clearly(tmp_path, meta_edit, array_edit, message):
    good = random_planner().save(tmp_path / "good.npz")
    bad = _rewrite(good, tmp_path / "bad.npz", meta_edit, array_edit)
    with pytest.raises(ValueError, match=message) as info:
        MLPPlanner.load(bad)
    assert "bad.npz" in str(info.value)


def test_not_a_model_file(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_text("hello")
    with pytest.raises(ValueError, match="not a readable"):
        MLPPlanner.load(junk)
    np.savez(tmp_path / "plain.npz", w=np.zeros(3))
    with pytest.raises(ValueError, match="no 'metadata'"):
        MLPPlanner.load(tmp_path / "plain.npz")
    with pytest.raises(FileNotFoundError):
        MLPPlanner.load(tmp_path / "missing.npz")


def test_shipped_default_planner_loads_and_is_bounded():
    planner = load_default_planner()
    obs = sample_observations(2000, np.random.default_rng(3), PARAMS, DataConfig())
    a_x, a_y = planner(obs, PARAMS)
    assert np.all((-PARAMS.a_x_d <= a_x) & (a_x <= PARAMS.a_x_a)) and np.all(np.abs(a_y) <= PARAMS.a_y_m)
    # An open gap at the start of a lane change: move toward the target lane.
    assert np.all(planner(open_gap_observation(), PARAMS)[1] > 0.5)


def test_inference_imports_no_torch_or_onnx():
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "import safelane.cli, safelane.training.train\n"
        "from safelane.planners.nn import load_default_planner\n"
        "from safelane.planners.teacher import OptimalControlTeacher\n"
        "load_default_planner()\n"
        "heavy = sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'onnx', 'onnxruntime'))\n"
        "assert not heavy, heavy\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
