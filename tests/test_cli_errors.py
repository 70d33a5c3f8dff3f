"""The command line's error path (docs/usage.md, "Bad input → behaviour"): one line naming the option or file and
exit status 2 for a bad input; ``--debug`` / ``SAFELANE_DEBUG=1`` add the full traceback; warnings as one line;
Ctrl-C says what was kept. Most tests stub the expensive work: they are about what the user reads."""

from __future__ import annotations

import json
import warnings

import pandas as pd
import pytest
from typer.testing import CliRunner

from safelane import Params
from safelane.cli import app, plain_message
from safelane.experiments import calibration
from safelane.experiments import falsify as fz
from safelane.experiments import reproduce as reproduce_module
from safelane.sim.engine import SimConfig

runner = CliRunner()


def _boom(exc: BaseException):
    def fake(*args, **kwargs):
        raise exc

    return fake


# -- --debug and SAFELANE_DEBUG=1 ---------------------------------------------------------------------------------
@pytest.mark.parametrize("error", [RuntimeError("boom inside"), EOFError("boom inside")])
@pytest.mark.parametrize("how", ["option", "env"])
def test_debug_shows_the_full_traceback(monkeypatch, tmp_path, error, how):
    # Click turned an EOFError under --debug into a bare "Aborted!"; now every error shows its traceback.
    monkeypatch.setattr("safelane.planners.nn.load_default_planner", _boom(error))
    args = ["export-onnx", "--out", str(tmp_path / "m.onnx")]
    if how == "option":
        result = runner.invoke(app, ["--debug", *args])
    else:
        result = runner.invoke(app, args, env={"SAFELANE_DEBUG": "1"})
    assert result.exit_code == 1
    assert "Traceback (most recent call last)" in result.stderr and "in export_onnx" in result.stderr
    assert f"{type(error).__name__}: boom inside" in result.stderr and "Aborted" not in result.output


def test_without_debug_an_unexpected_error_is_one_line(monkeypatch, tmp_path):
    monkeypatch.setattr("safelane.planners.nn.load_default_planner", _boom(RuntimeError("boom\ninside")))
    result = runner.invoke(app, ["export-onnx", "--out", str(tmp_path / "m.onnx")], env={"SAFELANE_DEBUG": "0"})
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert result.stderr.strip() == "Error: RuntimeError: boom inside (run 'safelane --debug ...' for the traceback)"


def test_debug_shows_where_a_bad_input_arose_and_still_names_the_option(tmp_path):
    args = ["simulate", "--samples", "-1", "--out", str(tmp_path)]
    normal = runner.invoke(app, args)
    debug = runner.invoke(app, ["--debug", *args])
    for result in (normal, debug):
        assert result.exit_code == 2
        assert result.stderr.strip().splitlines()[-1].startswith("Error: Invalid value for --samples:")
    assert "Traceback" not in normal.output
    assert "Traceback (most recent call last)" in debug.stderr and "InputError: samples must be" in debug.stderr


# -- files and options named -------------------------------------------------------------------------------------
def test_an_empty_npz_is_an_input_error_naming_the_file(tmp_path):
    empty = tmp_path / "model.npz"
    empty.write_bytes(b"")
    result = runner.invoke(app, ["export-onnx", str(empty), "--out", str(tmp_path / "m.onnx")])
    assert result.exit_code == 2, result.output
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("Error: Invalid value for MODEL:") and str(empty) in last and "empty" in last
    assert "EOFError" not in result.output and not (tmp_path / "m.onnx").exists()


def test_numpy_scalars_are_shown_as_plain_numbers(tmp_path):
    assert plain_message("got np.float64(50.0) and np.int64(3),\n np.True_ stays; np.str_('x')") == (
        "got 50.0 and 3, np.True_ stays; 'x'"
    )
    result = runner.invoke(app, ["check", "--promise", "50", "--chain-p", "40", "--chain-v", "30"])
    assert result.exit_code == 2, result.output
    assert "50.0" in result.output and "np.float64" not in result.output
    assert "--promise" in result.output.split("Error")[-1]  # the chain's error names the option that gave it


def test_the_chains_errors_name_the_option():
    speeds = runner.invoke(app, ["check", "--chain-p", "40", "--chain-v", "-3"])
    assert speeds.exit_code == 2 and "Invalid value for --chain-v" in speeds.output, speeds.output


def test_an_input_error_naming_an_option_names_it_in_the_message(tmp_path):
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("x")
    result = runner.invoke(app, ["simulate", "--samples", "2", "--out", str(not_a_folder)])
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines()[-1].startswith("Error: Invalid value for --out:")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "file not found; give a scenario dump"),
        ('{"spec": 1,,}', "line 1, column 12: invalid JSON"),
        ("[1, 2]", "not a falsify scenario dump (missing 'spec'"),
        ('{"spec": {}}', "not a falsify scenario dump (missing 'params'"),
    ],
)
def test_replay_names_the_option_and_the_file(tmp_path, content, message):
    path = tmp_path / "worst.json"
    if content is not None:
        path.write_text(content)
    result = runner.invoke(app, ["falsify", "--replay", str(path)])
    assert result.exit_code == 2, result.output
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith(f"Error: Invalid value for --replay: {str(path)!r}: ") and message in last
    assert "Errno" not in last and "(char " not in last


def test_replay_takes_a_run_folder(tmp_path, monkeypatch):
    (tmp_path / "worst.json").write_text(json.dumps({k: 0 for k in ("spec", "params", "sim", "seed",
                                                                    "decel_last_max", "use_hooks")}))  # fmt: skip
    seen = []
    monkeypatch.setattr(fz, "replay", lambda record: seen.append(record) or pd.DataFrame())
    result = runner.invoke(app, ["falsify", "--replay", str(tmp_path)])
    assert result.exit_code == 0 and seen[0]["seed"] == 0 and "not simulated" in result.output


def test_falsify_refuses_endless_minutes_before_searching(monkeypatch, tmp_path):
    monkeypatch.setattr(fz, "falsify", _boom(AssertionError("the search ran")))
    result = runner.invoke(app, ["falsify", "--minutes", "inf", "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    assert "Invalid value for --minutes: must be a finite number of minutes >= 0; got inf" in result.stderr
    assert not (tmp_path / "o").exists()


# -- warnings ------------------------------------------------------------------------------------------------------
def test_a_warning_is_one_clean_line_once(monkeypatch, tmp_path):
    class Planner:
        def to_onnx(self, path):
            for _ in range(3):
                warnings.warn("L(N+1) brakes harder\n  than assumed", UserWarning, stacklevel=1)
            path.write_text("onnx")
            return path

    monkeypatch.setattr("safelane.planners.nn.load_default_planner", Planner)
    result = runner.invoke(app, ["export-onnx", "--out", str(tmp_path / "m.onnx")])
    assert result.exit_code == 0, result.output
    assert result.stderr.splitlines() == ["Warning: L(N+1) brakes harder than assumed"]
    assert "UserWarning" not in result.output and "warnings.warn(" not in result.output


# -- Ray -----------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("address", "expected"), [(None, "starting a local Ray runtime (~40 s"),
                                                   ("head:6379", "connecting to the Ray cluster at head:6379")])
def test_ray_start_is_announced_before_it_begins(monkeypatch, capsys, address, expected):
    from safelane.cli import _backend
    from safelane.parallel import Backend

    events = []

    class FakeRay:
        @staticmethod
        def is_initialized():
            return False

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr("safelane.ray_cluster.import_ray", lambda: FakeRay)
    monkeypatch.setattr("safelane.ray_cluster._local_cluster", lambda ray: None)
    monkeypatch.setattr("safelane.parallel.connect_ray", lambda *a: events.append(capsys.readouterr().err) or False)
    with _backend.session(Backend("ray", 2, address)):
        pass
    assert len(events) == 1 and expected in events[0]  # said before connecting
    with _backend.session(2):  # local processes: nothing to say
        pass
    assert capsys.readouterr().err == ""


# -- calibrate -----------------------------------------------------------------------------------------------------
def _fake_calibrate(stop_after: int | None = None):
    def fake(candidates, samples, refine, finalists, final_samples, seed, on_candidate, workers):
        point = {k: lo for k, (lo, _) in calibration.SEARCH_SPACE.items()}
        for i in range(candidates + refine + finalists):
            if i == stop_after:
                raise KeyboardInterrupt
            on_candidate(i, point, 0.5 - 0.01 * i)
        # As the real search: the result starts from the shipped preset's name.
        return calibration.Preset("paper", Params(), SimConfig(), {"loss_mean_abs_diff": 0.4}), pd.DataFrame(
            [{**point, "loss": 0.5, "stage": 1}]
        )

    return fake


def test_calibrate_refuses_a_bad_name_before_it_runs(monkeypatch, tmp_path):
    monkeypatch.setattr(calibration, "calibrate", _boom(AssertionError("the calibration ran")))
    for args in (["--name", "../evil", "--install"], ["--name", "a b"], ["--name", ""]):
        result = runner.invoke(app, ["calibrate", *args, "--out", str(tmp_path / "o"),
                                     "--preset-dir", str(tmp_path / "p")])  # fmt: skip
        assert result.exit_code == 2, result.output
        assert "Invalid value for --name:" in result.stderr and "letters, digits, '-' or '_'" in result.stderr
    assert not (tmp_path / "o").exists() and not (tmp_path / "p").exists()


def test_calibrate_writes_its_result_under_the_users_name(monkeypatch, tmp_path):
    monkeypatch.setattr(calibration, "calibrate", _fake_calibrate())
    result = runner.invoke(app, ["calibrate", "--candidates", "2", "--refine", "0", "--finalists", "1",
                                 "--name", "mine", "--out", str(tmp_path)])  # fmt: skip
    assert result.exit_code == 0, result.output
    (run,) = tmp_path.iterdir()
    assert calibration.load_preset(run / "preset.yaml").name == "mine"
    assert json.loads((run / "run.json").read_text())["name"] == "mine"


def test_calibrate_help_names_the_true_origin_of_the_shipped_presets():
    import inspect

    from safelane.cli.calibrate import calibrate as command

    help_text = " ".join(runner.invoke(app, ["calibrate", "--help"]).output.split())
    assert "the settings that built the shipped 'paper_numbers' preset" in help_text
    assert "'paper' preset comes from 'python -m safelane.experiments.structure'" in help_text
    # ... and they are true: the defaults are paper_numbers' recorded command, and paper's is the structure search.
    defaults = {n: p.default.default for n, p in inspect.signature(command).parameters.items()}
    expected = (f"safelane calibrate --candidates {defaults['candidates']} --samples {defaults['samples']} --refine "
                f"{defaults['refine']} --finalists {defaults['finalists']} --final-samples {defaults['final_samples']}"
                f" --seed {defaults['seed']}")  # fmt: skip
    assert " ".join(calibration.load_preset("paper_numbers").meta["command"].split()) == expected
    assert calibration.load_preset("paper").meta["command"].startswith("python -m safelane.experiments.structure")


def test_calibrate_ctrl_c_keeps_the_scored_candidates(monkeypatch, tmp_path):
    monkeypatch.setattr(calibration, "calibrate", _fake_calibrate(stop_after=3))
    result = runner.invoke(app, ["calibrate", "--candidates", "5", "--out", str(tmp_path)])
    assert result.exit_code == 130
    (run,) = tmp_path.iterdir()
    scored = pd.read_csv(run / "candidates.csv")
    assert list(scored["loss"]) == [0.5, 0.49, 0.48] and set(scored["stage"]) == {1}
    info = json.loads((run / "run.json").read_text())
    assert info["status"] == "interrupted" and info["candidates_scored"] == 3 and info["finished_utc"]
    assert f"kept the 3 candidates scored so far in {run / 'candidates.csv'}" in result.stderr
    assert "Interrupted (Ctrl-C); exit status 130." in result.stderr


# -- Ctrl-C elsewhere ----------------------------------------------------------------------------------------------
def test_reproduce_ctrl_c_says_nothing_was_kept(monkeypatch, tmp_path):
    monkeypatch.setattr(reproduce_module, "reproduce", _boom(KeyboardInterrupt()))
    result = runner.invoke(app, ["reproduce", "--quick", "--out", str(tmp_path), "--no-progress"])
    assert result.exit_code == 130
    assert "interrupted: the experiments had not finished; nothing was kept" in result.stderr


def test_falsify_ctrl_c_keeps_the_report_so_far(monkeypatch, tmp_path):
    def fake(scenarios, minutes, seed, method, *, on_batch, **kwargs):
        report = fz.Report(seed=seed, methods=("random",), hooks=True, profiles=True, generated=12, simulated=10)
        on_batch(report)
        raise KeyboardInterrupt

    monkeypatch.setattr(fz, "falsify", fake)
    result = runner.invoke(app, ["falsify", "--out", str(tmp_path), "--no-progress"])
    assert result.exit_code == 130
    (run,) = tmp_path.iterdir()
    assert json.loads((run / "report.json").read_text())["scenarios_simulated"] == 10
    info = json.loads((run / "run.json").read_text())
    assert info["status"] == "interrupted" and info["scenarios_simulated"] == 10
    assert "interrupted after 10 simulated scenarios: their report is kept" in result.stderr


# -- train ---------------------------------------------------------------------------------------------------------
def test_train_ctrl_c_says_what_was_dropped(monkeypatch, tmp_path):
    pytest.importorskip("torch")
    monkeypatch.setattr("safelane.training.train.train", _boom(KeyboardInterrupt()))
    result = runner.invoke(app, ["train", "--out", str(tmp_path)])
    assert result.exit_code == 130
    assert not any(tmp_path.iterdir())
    assert "interrupted: nothing was written yet; removed the run folder" in result.stderr


def test_train_progress_goes_to_stderr_and_stdout_is_the_json_summary(tmp_path):
    pytest.importorskip("torch")
    import yaml

    tiny = {"data": {"n_states": 300}, "teacher": {"n_candidates": 8, "n_iters": 1, "n_refine": 1},
            "model": {"hidden": [8]}, "optim": {"max_epochs": 1}, "dagger": {"rounds": 0}, "export_onnx": False}
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(tiny))
    result = runner.invoke(app, ["train", "--config", str(tmp_path / "tiny.yaml"), "--out", str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)  # nothing but the summary
    assert summary["epochs"] == 1 and summary["out"].startswith(str(tmp_path / "o"))
    assert "round 0 epochs" in result.stderr and "labelling states" in result.stderr


def test_a_file_error_names_the_file_without_errno(monkeypatch, tmp_path):
    missing = str(tmp_path / "gone.csv")
    monkeypatch.setattr("safelane.planners.nn.load_default_planner",
                        _boom(FileNotFoundError(2, "No such file or directory", missing)))  # fmt: skip
    result = runner.invoke(app, ["export-onnx", "--out", str(tmp_path / "m.onnx")])
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines()[-1] == (
        f"Error: Invalid value for MODEL: {missing!r}: No such file or directory"
    )
    folder = runner.invoke(app, ["export-onnx", str(tmp_path), "--out", str(tmp_path / "m.onnx")])
    assert folder.exit_code == 2 and "Errno" not in folder.output
    assert f"Invalid value for MODEL: {str(tmp_path)!r} is a folder; give a model.npz file" in folder.stderr


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["falsify", "--scenarios", "-1"], "Invalid value for '--scenarios' / '-n': Input should be greater than or "
                                           "equal to 0; got -1"),
        (["falsify", "--minutes=nan"], "Invalid value for '--minutes' / '-m': Input should be greater than or equal "
                                       "to 0; got nan"),
        (["calibrate", "--candidates", "0"], "Invalid value for '--candidates': Input should be greater than or equal "
                                             "to 1; got 0"),
    ],
)
def test_clicks_own_range_checks_show_the_value(args, line, tmp_path):
    result = runner.invoke(app, [*args, "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines()[-1] == f"Error: {line}"
    assert not (tmp_path / "o").exists()


# -- falsify --others-decel ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("world", ["paper", "realistic"])
def test_falsify_others_decel_reaches_the_search(monkeypatch, tmp_path, world):
    seen = {}

    def fake(scenarios, minutes, seed, method, *, setting, on_batch, **kwargs):
        seen["setting"] = setting
        report = fz.Report(seed=seed, methods=("random",), hooks=True, profiles=True, generated=2, simulated=2)
        on_batch(report)
        return report

    monkeypatch.setattr(fz, "falsify", fake)
    result = runner.invoke(app, ["falsify", "--others-decel", "9.5", "--world", world, "--minutes", "0",
                                 "--out", str(tmp_path), "--no-progress"])  # fmt: skip
    assert result.exit_code == 0, result.output
    setting = seen["setting"]
    assert setting.params.others_decel == 9.5 and setting.params.a_x_d == 8.0 and setting.world == world
    (run,) = tmp_path.iterdir()
    assert json.loads((run / "run.json").read_text())["others_decel"] == 9.5


def test_falsify_others_decel_out_of_range_names_the_option(tmp_path):
    result = runner.invoke(app, ["falsify", "--others-decel", "-1", "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert "--others-decel" in result.stderr and "greater than or equal to 0" in result.stderr
    assert not tmp_path.exists() or not any(tmp_path.iterdir())
