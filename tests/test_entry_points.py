"""Every entry point as a user expects (issue 14): one-line errors naming the field, run folders with provenance,
``--out`` checked before work, presets everywhere, one seeding scheme. One test per item; see docs/usage.md."""

from __future__ import annotations

import inspect
import json
import re
import shlex
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import typer
from typer.testing import CliRunner

import safelane
from safelane import Params, SimConfig, simulate
from safelane.cli import app
from safelane.errors import InputError
from safelane.experiments.calibration import calibrate
from safelane.experiments.grid import Cell, run_cells
from safelane.sim import ScenarioConfig
from safelane.sim.preset import PRESET_DIR, load_preset

runner = CliRunner()
TINY = ["--planner", "CV_none", "--leaders", "1", "--decel", "4", "--samples", "4", "--seed", "3", "--no-progress"]
SHORT = SimConfig(horizon_s=3.0)
ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def _user_presets(tmp_path_factory, monkeypatch):
    """User presets of the test session only (never the real ~/.config)."""
    monkeypatch.setenv("SAFELANE_PRESET_DIR", str(tmp_path_factory.mktemp("user_presets")))


def invoke(*args: str):
    return runner.invoke(app, [str(a) for a in args])


def assert_usage_error(result, *needles: str) -> None:
    """Exit status 2, an ``Error:`` line containing every needle, no traceback."""
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    error = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(error) == 1, result.output
    for needle in needles:
        assert needle in error[0], (needle, error[0])


# ---------------------------------------------------------------- bad files, every command that reads one
BAD_FILES = {
    "syntax": ("p_m: 7.0\ndt: [0.1,\n", ("line 3", "invalid YAML")),
    "unknown key": ("p_m: 7.0\nbogus_key: 1\n", ("unknown field 'bogus_key'", "allowed: a_x_a")),
    "negative": ("p_m: -1\n", ("'p_m' = -1", "greater than 0")),
    "nan": ("p_m: .nan\n", ("'p_m' = nan", "finite")),
    "not a mapping": ("- 1\n- 2\n", ("expected a mapping",)),
}


def _bad_file(tmp_path: Path, kind: str) -> tuple[Path, tuple[str, ...]]:
    text, needles = BAD_FILES[kind]
    path = tmp_path / f"{kind.replace(' ', '_')}.yaml"
    path.write_text(text)
    return path, (str(path), *needles)


@pytest.mark.parametrize("kind", list(BAD_FILES))
def test_check_params_file_errors_name_file_line_and_field(tmp_path, kind):
    path, needles = _bad_file(tmp_path, kind)
    assert_usage_error(invoke("check", "--params", path), "--params", *needles)


@pytest.mark.parametrize("command", ["check", "simulate"])
def test_missing_file_and_directory_are_one_line_errors(tmp_path, command):
    out = ["--out", tmp_path / "out"] if command == "simulate" else []
    assert_usage_error(invoke(command, "--params", tmp_path / "nope.yaml", *out), "nope.yaml", "not found")
    assert_usage_error(invoke(command, "--params", tmp_path, *out), str(tmp_path), "is a directory")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_simulate_params_syntax_error(tmp_path):
    path, needles = _bad_file(tmp_path, "syntax")
    assert_usage_error(invoke("simulate", *TINY, "--params", path, "--out", tmp_path / "o"), *needles)


def test_reproduce_preset_syntax_error_and_unknown_field(tmp_path):
    path, needles = _bad_file(tmp_path, "syntax")
    assert_usage_error(invoke("reproduce", "--preset", path, "--out", tmp_path / "o"), "--preset", *needles)
    preset = tmp_path / "p.yaml"
    preset.write_text("params:\n  p_m: 7.0\n  colour: red\n")
    assert_usage_error(invoke("reproduce", "--preset", preset, "--out", tmp_path / "o"), "'params.colour'")
    assert not (tmp_path / "o").exists()


def test_train_config_syntax_error_and_bad_value(tmp_path):
    path, needles = _bad_file(tmp_path, "syntax")
    assert_usage_error(invoke("train", "--config", path, "--out", tmp_path / "o"), "--config", *needles)
    cfg = tmp_path / "t.yaml"
    cfg.write_text("optim:\n  lr: -1\n")
    assert_usage_error(invoke("train", "--config", cfg, "--out", tmp_path / "o"), "'optim.lr' = -1")


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--planner", "CV_bogus"], ("--planner", "CV_bogus", "CV_all")),
        (["--p-v", "2"], ("--p-v", "p_v", "[0, 1]")),
        (["--samples", "0"], ("--samples", "positive integer")),
        (["--seed", "-1"], ("--seed", "non-negative")),
        (["--leaders", "-2"], ("--leaders", "non-negative")),
        (["--assessment", "oracle"], ("--assessment", "oracle", "truth")),
        (["--nominal", "nope"], ("--nominal", "nope", "expert, mlp, teacher")),
        (["--preset", "nope"], ("--preset", "'nope' not found", "available: paper")),
    ],
)
def test_simulate_bad_options_name_the_option(tmp_path, args, needles):
    assert_usage_error(invoke("simulate", *TINY, "--out", tmp_path, *args), *needles)
    assert not any(tmp_path.iterdir())  # nothing written


def test_check_and_reproduce_name_the_option():
    assert_usage_error(invoke("check", "--ego-vx", "-5"), "--ego-vx", "ego_vx must be >= 0; got -5.0")
    assert_usage_error(invoke("reproduce", "--only", "bogus"), "--only", "'bogus'", "table1")


def test_debug_shows_the_traceback_and_version(tmp_path):
    plain = invoke("check", "--params", tmp_path / "nope.yaml")
    assert plain.exit_code == 2 and "Traceback" not in plain.output
    debug = invoke("--debug", "check", "--params", tmp_path / "nope.yaml")
    # The full traceback of where the bad input arose, then the same one line and status (tests/test_cli_errors.py).
    assert debug.exit_code == 2 and "Traceback (most recent call last)" in debug.output
    assert "safelane.errors.InputError: Params file not found" in debug.output
    version = invoke("--version")
    assert version.exit_code == 0 and version.output.strip() == f"safelane {safelane.__version__}"


def test_subprocess_error_has_no_traceback(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("p_m: [1,\n")
    cmd = [sys.executable, "-c", "from safelane.cli import app; app()", "check", "--params", str(bad)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "invalid YAML" in proc.stderr and "line 2" in proc.stderr


# ---------------------------------------------------------------- outputs: run folders, --out, interruptions
def test_preset_runs_do_not_overwrite_plain_runs_and_record_provenance(tmp_path):
    for extra in ([], ["--preset", "paper", "--nominal", "mlp"]):
        assert invoke("simulate", *TINY, "--out", tmp_path, *extra).exit_code == 0
    runs = sorted(tmp_path.iterdir())
    assert len(runs) == 2 and sum(r.name.endswith("seed3-paper-mlp") for r in runs) == 1
    infos = [json.loads((r / "run.json").read_text()) for r in runs]
    by_nominal = {i["nominal"]: i for i in infos}
    assert set(by_nominal) == {"expert", "mlp"}
    assert by_nominal["mlp"]["preset"]["name"] == "paper" and by_nominal["mlp"]["preset"]["source"]
    for info in infos:
        assert {"command", "samples", "seed", "assessment", "versions", "planner", "status"} <= set(info)
        assert info["status"] == "complete" and info["samples"] == 4


@pytest.mark.parametrize("command", ["simulate", "train", "calibrate", "reproduce", "falsify"])
def test_unwritable_out_fails_before_any_work(tmp_path, monkeypatch, command):
    import safelane.experiments.calibration as calibration
    import safelane.experiments.falsify as falsify_module
    import safelane.experiments.reproduce as reproduce_module
    import safelane.sim as sim_module
    import safelane.training.train as train_module

    def forbidden(*args, **kwargs):
        raise AssertionError("work started before --out was checked")

    for module, name in ((sim_module, "simulate"), (train_module, "train"), (calibration, "calibrate"),
                         (reproduce_module, "reproduce"), (falsify_module, "falsify")):  # fmt: skip
        monkeypatch.setattr(module, name, forbidden)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    args = TINY if command == "simulate" else []
    assert_usage_error(invoke(command, *args, "--out", blocker), "--out", str(blocker), "is a file")
    assert_usage_error(invoke(command, *args, "--out", blocker / "sub"), "--out", "not a writable folder")


def test_interrupted_simulate_leaves_no_run_folder(tmp_path, monkeypatch):
    import safelane.sim as sim_module

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(sim_module, "simulate", interrupted)
    result = invoke("simulate", *TINY, "--out", tmp_path)
    assert result.exit_code == 130 and "Traceback" not in result.output
    assert not any(tmp_path.iterdir())


def test_interrupted_reproduce_leaves_no_run_folder(tmp_path, monkeypatch):
    import safelane.experiments.reproduce as reproduce_module

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(reproduce_module, "_run_all", interrupted)
    with pytest.raises(KeyboardInterrupt):
        reproduce_module.reproduce(tmp_path, quick=True, progress=False)
    assert not any(tmp_path.iterdir())


def test_unexpected_errors_are_one_line_with_status_1(tmp_path, monkeypatch):
    import safelane.sim as sim_module

    def broken(*args, **kwargs):
        raise RuntimeError("something internal\nover two lines")

    monkeypatch.setattr(sim_module, "simulate", broken)
    result = invoke("simulate", *TINY, "--out", tmp_path)
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "Error: RuntimeError: something internal over two lines" in result.output and "--debug" in result.output
    assert not any(tmp_path.iterdir())  # a run that wrote nothing is removed


# ---------------------------------------------------------------- presets everywhere
def test_top_level_load_preset_and_simulate_preset():
    preset = safelane.load_preset("paper")
    assert preset.params.a_x_d != Params().a_x_d and preset.source == str(PRESET_DIR / "paper.yaml")
    by_name = simulate("CV_all", 1, 4.0, 8, 0, preset="paper", config=SHORT).table
    by_hand = simulate("CV_all", 1, 4.0, 8, 0, params=preset.params, config=SHORT, nominal=preset.nominal()).table
    pd.testing.assert_frame_equal(by_name, by_hand)


def test_check_takes_a_preset_a_preset_file_and_a_leader_chain(tmp_path):
    result = invoke("check", "--preset", "paper")
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert out["params"]["a_x_d"] == load_preset("paper").params.a_x_d and out["l1_decel"] == out["params"]["a_x_d"]
    copy = tmp_path / "mine.yaml"
    copy.write_text((PRESET_DIR / "paper.yaml").read_text())
    assert json.loads(invoke("check", "--preset", copy).output)["params"] == out["params"]
    chain = invoke("check", "--preset", "paper", "--chain-p", "40", "--chain-p", "60", "--chain-v", "30",
                   "--chain-v", "30")  # fmt: skip
    assert chain.exit_code == 0, chain.output
    assert json.loads(chain.output)["l1_decel"] < out["l1_decel"]  # the connected chain bounds L1's braking
    assert_usage_error(invoke("check", "--chain-p", "40"), "--chain-v", "one --chain-v per --chain-p")


def test_user_presets_live_outside_the_package(tmp_path, monkeypatch):
    from safelane.sim.preset import install_preset, user_preset_dir

    monkeypatch.setenv("SAFELANE_PRESET_DIR", str(tmp_path / "user"))
    assert user_preset_dir() == tmp_path / "user"
    path = install_preset(load_preset("paper"), "mine")
    assert path.parent == tmp_path / "user" and not path.is_relative_to(PRESET_DIR.parent)
    assert load_preset("mine").params == load_preset("paper").params
    with pytest.raises(InputError, match="shipped preset"):
        install_preset(load_preset("paper"), "paper")
    result = invoke("simulate", *TINY, "--preset", "mine", "--out", tmp_path / "o")
    assert result.exit_code == 0, result.output


def test_calibrate_defaults_are_the_ones_that_built_the_shipped_preset():
    # `safelane calibrate` (cells only) built paper_numbers; `paper` comes from the structure-aware calibration.
    command = load_preset("paper_numbers").meta["command"]
    recorded = dict(zip(*[iter(shlex.split(command)[2:])] * 2, strict=True))
    api = inspect.signature(calibrate).parameters
    cli = {p.name: p.default for p in typer.main.get_command(app).commands["calibrate"].params}
    for option, value in recorded.items():
        name = option.lstrip("-").replace("-", "_")
        assert str(api[name].default) == value and str(cli[name]) == value, option


# ---------------------------------------------------------------- one seeding scheme
def test_simulate_and_the_report_grid_give_the_same_cell():
    preset = load_preset("paper")
    api = simulate("CV_all", 1, 4.0, 30, 0, preset="paper").table
    grid = run_cells([Cell("CV_all", 1, 4.0)], 30, 0, params=preset.params, config=preset.sim,
                     nominal=preset.nominal()).drop(columns="cell")  # fmt: skip
    pd.testing.assert_frame_equal(api, grid)
    # ... whichever other cells share the grid (a report runs many at once).
    crowd = run_cells([Cell("CV_none", 3, 2.0), Cell("CV_all", 1, 4.0)], 30, 0, params=preset.params,
                      config=preset.sim, nominal=preset.nominal())  # fmt: skip
    pd.testing.assert_frame_equal(api, crowd[crowd["cell"] == 1].drop(columns="cell").reset_index(drop=True))


# ---------------------------------------------------------------- Python API: errors name the argument
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(decel="5"), r"decel .* got '5' \(str\)"),
        (dict(samples=True), r"samples must be a positive integer; got True \(bool\)"),
        (dict(seed=1.5), r"seed must be a non-negative integer; got 1.5 \(float\)"),
        (dict(seed=-1), r"seed must be a non-negative integer"),
        (dict(planner=3), r"planner must be a variant name"),
        (dict(params={"p_m": -1.0}), r"params: field 'p_m' = -1.0"),
        (dict(params=[1, 2]), r"params must be a Params or a mapping"),
        (dict(config={"horizon": 3}), r"config: unknown field 'horizon'"),
        (dict(nominal="nope"), r"unknown nominal planner 'nope'; choose one of expert, mlp, teacher"),
        (dict(nominal=3), r"nominal must be a registered name"),
        (dict(preset="nope"), r"preset 'nope' not found \(available: .*paper"),
        (dict(preset=3), r"preset must be a preset name"),
        (dict(config=SimConfig(horizon_s=0.05)), r"config.horizon_s=0.05 is shorter than one control period"),
        (dict(scenario=ScenarioConfig(promise_decel=9.0)), r"scenario.promise_decel=9.0 exceeds params.a_x_d=8.0"),
        (dict(scenario=ScenarioConfig(promise_accel=3.0)), r"scenario.promise_accel=3.0 exceeds params.a_x_a=2.5"),
    ],
)
def test_simulate_api_errors_name_the_argument(kwargs, match):
    with pytest.raises(InputError, match=match):
        simulate(**{"samples": 2, **kwargs})


def test_simulate_api_accepts_names_and_mappings():
    by_name = simulate("CV_all", 1, 4.0, 3, 0, nominal="mlp", config={"horizon_s": 2.0}, params={"p_m": 7.5})
    assert len(by_name.table) == 3
    one = simulate("CV_all", 1, 4.0, 3, 0, config=SHORT, trace=True, trace_limit=2)
    assert one.trace["scenario_id"].nunique() == 2


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(gap=(22.0, 17.0)), r"gap=\(22.0, 17.0\) must satisfy 0 < lo <= hi"),
        (dict(ego_speed=(31.0, 29.0)), r"ego_speed=\(31.0, 29.0\) must satisfy 0 <= lo <= hi"),
        (dict(gap=(0.0, 3.0)), r"gap=\(0.0, 3.0\)"),
    ],
)
def test_scenario_config_rejects_reversed_ranges(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ScenarioConfig(**kwargs)


def test_overlapping_initial_vehicles_warn():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        simulate("CV_all", 1, 4.0, 2, 0, config=SHORT, scenario=ScenarioConfig(gap=(4.0, 4.5)))
    assert any("initial vehicles overlap" in str(w.message) for w in caught)


# ---------------------------------------------------------------- the remaining items
def test_simulate_help_lists_every_variant_and_commands_exist():
    from safelane.planners.variants import VARIANT_NAMES

    text = invoke("simulate", "--help").output.replace("\n", " ")
    for name in VARIANT_NAMES:
        assert name in text
    assert "..." not in text.split("--planner")[1].split("--leaders")[0]
    assert "export-onnx" in invoke("--help").output


def test_export_onnx(tmp_path):
    pytest.importorskip("onnx")
    result = invoke("export-onnx", "--out", tmp_path / "m.onnx")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "m.onnx").stat().st_size > 1000
    assert_usage_error(invoke("export-onnx", tmp_path / "none.npz", "--out", tmp_path / "m.onnx"), "not found")
    assert_usage_error(invoke("export-onnx", "--out", tmp_path / "m.txt"), "--out", ".onnx")


def test_summary_bounds_are_exact_at_zero_and_one():
    from safelane.sim.metrics import wilson_interval

    lo, hi = wilson_interval(np.array([0, 1000]), np.array([1000, 1000]))
    assert lo[0] == 0.0 and hi[1] == 1.0
    for path in (ROOT / "docs" / "results" / "data").glob("*_summary.csv"):
        frame = pd.read_csv(path)
        lows = frame[[c for c in frame.columns if c.endswith("_lo")]].to_numpy()
        assert not ((lows > 0) & (lows < 1e-12)).any(), path


def test_committed_report_links_only_committed_files():
    report = ROOT / "docs" / "results" / "report.md"
    for target in re.findall(r"\]\(([^)#]+)\)", report.read_text()):
        if "://" not in target:
            assert (report.parent / target).exists(), target


def test_reproduce_prints_the_html_report(tmp_path, monkeypatch):
    import safelane.experiments.reproduce as reproduce_module

    monkeypatch.setattr(reproduce_module, "reproduce", lambda out, **kw: tmp_path / "run")
    result = invoke("reproduce", "--quick", "--out", tmp_path, "--no-progress")
    assert result.exit_code == 0 and str(tmp_path / "run" / "report.html") in result.output


def test_no_nan_slips_through_the_cli(tmp_path):
    # The option parser accepts 'nan'; the API's check rejects it, naming the option.
    assert_usage_error(invoke("simulate", *TINY, "--decel", "nan", "--out", tmp_path), "--decel", "nan")
