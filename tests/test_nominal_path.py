"""Issue 31: a trained model file as the nominal planner (``simulate(nominal="model.npz")``, ``--nominal PATH``),
and the summaries name the preset and the nominal planner (``paper`` with ``nominal="mlp"`` is not the paper's
numbers, and now says so)."""

from __future__ import annotations

import importlib.util
import json
import shutil
import warnings
from importlib.resources import files
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from safelane.cli import app
from safelane.errors import InputError
from safelane.sim import simulate

cli = CliRunner()
CELL = dict(planner="CV_all", n_leaders=1, decel=4.0, samples=12, seed=3)
SIM = ["simulate", "--leaders", "1", "--decel", "4", "--samples", "12", "--seed", "3", "--no-progress"]


def _flat(text: str) -> str:
    return " ".join(text.split())


@pytest.fixture
def model(tmp_path) -> Path:
    """The shipped ``mlp`` network, as a user's trained ``model.npz`` would lie on disk."""
    path = tmp_path / "trained" / "model.npz"
    path.parent.mkdir()
    shutil.copyfile(str(files("safelane") / "models" / "mlp_default.npz"), path)
    return path


def test_npz_file_gives_the_numbers_of_the_registered_network(model):
    by_name = simulate(**CELL, nominal="mlp")
    for value in (str(model), model):  # a string or a Path
        by_file = simulate(**CELL, nominal=value)
        pd.testing.assert_frame_equal(by_file.table, by_name.table)
        assert by_file.nominal == str(model)


def test_onnx_file_runs_the_same_network(model, tmp_path):
    if importlib.util.find_spec("onnxruntime") is None or importlib.util.find_spec("onnx") is None:
        pytest.skip("onnx/onnxruntime not installed (pip install 'safelane[train]'): the .onnx path is not tested")
    from safelane.planners.nn import MLPPlanner

    onnx = MLPPlanner.load(model).to_onnx(tmp_path / "model.onnx")
    by_name, by_file = simulate(**CELL, nominal="mlp"), simulate(**CELL, nominal=str(onnx))
    assert by_file.nominal == str(onnx)
    for col in ("success", "collision", "safety_violation", "completed"):  # float32 either way
        assert by_file.table[col].tolist() == by_name.table[col].tolist()


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("missing.npz", None, "model file not found"),
        ("empty.npz", b"", "not a readable .npz model file"),
        ("model.pt", b"x", "must be a .npz file"),
        ("folder.npz", "dir", "is a folder"),
    ],
)
def test_bad_model_file_names_the_argument_and_the_file(tmp_path, name, content, message):
    path = tmp_path / name
    if content == "dir":
        path.mkdir()
    elif content is not None:
        path.write_bytes(content)
    with pytest.raises(InputError, match=message) as err:
        simulate(**CELL, nominal=str(path))
    assert err.value.where == "nominal" and str(path) in str(err.value)
    result = cli.invoke(app, [*SIM, "--nominal", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    text = _flat(result.output)
    assert "--nominal" in text and message in text and name in text
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_foreign_npz_is_refused_by_load_nominal(tmp_path):
    from safelane.planners.registry import load_nominal

    path = tmp_path / "weights.npz"
    with path.open("wb") as fh:
        __import__("numpy").savez(fh, w=[1.0])
    with pytest.raises(InputError, match="no 'metadata' entry"):
        load_nominal(path)


def test_cli_model_file_runs_and_is_recorded(model, tmp_path):
    out = tmp_path / "out"
    result = cli.invoke(app, [*SIM, "--nominal", str(model), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert f"nominalplanner{model}" in "".join(result.output.split())  # Rich may wrap a long path anywhere
    (run,) = out.iterdir()
    assert run.name.endswith("-model")  # the file's name, not its whole path
    info = json.loads((run / "run.json").read_text())
    assert info["nominal"] == str(model)
    summary = pd.read_csv(run / "summary.csv")
    assert summary.loc[0, "nominal"] == str(model)
    table = pd.read_csv(run / "scenarios.csv")
    assert table["success"].tolist() == simulate(**CELL, nominal="mlp").table["success"].tolist()


def test_summary_names_the_preset_and_the_nominal_planner():
    plain = simulate(**CELL).summary()
    assert (plain.loc[0, "preset"], plain.loc[0, "nominal"]) == (None, "expert")
    paper = simulate(**CELL, preset="paper").summary()
    assert (paper.loc[0, "preset"], paper.loc[0, "nominal"]) == ("paper", "mlp_paper")
    teacher = simulate(**CELL, preset="paper", nominal="expert").summary()
    assert teacher.loc[0, "nominal"] == "expert (preset gains)"
    assert list(paper.columns[:3]) == ["preset", "nominal", "planner"]


def test_cli_summary_names_the_preset_and_the_nominal_planner(tmp_path):
    result = cli.invoke(app, [*SIM, "--preset", "paper", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    text = _flat(result.output)
    assert "preset paper" in text and "nominal planner mlp_paper" in text
    assert "Warning" not in text
    plain = cli.invoke(app, [*SIM, "--out", str(tmp_path / "plain")])
    assert "nominal planner expert" in _flat(plain.output) and "preset none" in _flat(plain.output)


def test_another_network_than_the_presets_warns(tmp_path):
    with pytest.warns(UserWarning, match=r"'mlp' is not the network of preset 'paper' \('mlp_paper'\)"):
        result = simulate(**CELL, preset="paper", nominal="mlp")
    assert result.summary().loc[0, "nominal"] == "mlp"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the preset's own network, its rule-based planner, a file: no warning
        simulate(**CELL, preset="paper")
        simulate(**CELL, preset="paper", nominal="expert")
    out = cli.invoke(app, [*SIM, "--preset", "paper", "--nominal", "mlp", "--out", str(tmp_path)])
    assert out.exit_code == 0, out.output
    assert "Warning: nominal planner 'mlp' is not the network of preset 'paper'" in _flat(out.output)


def test_simulate_help_does_not_pair_the_paper_preset_with_mlp():
    text = _flat(cli.invoke(app, ["simulate", "--help"]).output)
    assert "--preset paper --nominal mlp " not in text + " "
    assert "PATH.npz" in text and "nominal planner" in text


def test_reproduce_runs_a_model_file_instead_of_the_presets_network(model, tmp_path):
    """``reproduce --nominal PATH``: the experiments run the model (the same numbers as its registered twin), the
    report and run.json name it; a bad file is refused before any work."""
    args = ["reproduce", "--quick", "--only", "fig5_example", "--no-progress", "--workers", "1"]
    runs = {}
    for label, nominal in (("file", str(model)), ("name", "mlp"), ("preset", None)):
        out = tmp_path / label
        extra = [] if nominal is None else ["--nominal", nominal]
        result = cli.invoke(app, [*args, *extra, "--out", str(out)])
        assert result.exit_code == 0, result.output
        (run_dir,) = [p for p in out.iterdir() if p.is_dir()]
        runs[label] = run_dir
    trace = {k: (d / "data" / "fig5_example_trace.csv").read_bytes() for k, d in runs.items()}
    assert trace["file"] == trace["name"] != trace["preset"]  # mlp, not the paper preset's mlp_paper
    report = (runs["file"] / "report.md").read_text()
    assert str(model) in report and "a model file given with `--nominal`" in report
    bad = cli.invoke(app, [*args, "--nominal", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "bad")])
    assert bad.exit_code == 2 and "--nominal" in bad.output and "missing.npz" in bad.output, bad.output
    assert not (tmp_path / "bad").exists() or not any((tmp_path / "bad").iterdir())
