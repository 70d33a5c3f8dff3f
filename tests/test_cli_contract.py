"""One run-folder contract for every command that writes (docs/usage.md, "Where outputs go").

Every such command, run twice into the same ``--out`` at the smallest sizes it allows, writes two run folders
``OUT/<run-id>/``, each with a ``run.json`` that says what ran (``kind``, ``command``), when (``started_utc``,
``finished_utc``), with what (``versions``) and how it ended (``status``); the second run leaves the first one's
files as they were. The list of commands is checked against the app, so a new writing command cannot skip it.
"""

from __future__ import annotations

import hashlib
import json

import pytest
import yaml
from typer.testing import CliRunner

from safelane.cli import app

runner = CliRunner()

TINY_TRAIN = {
    "seed": 0,
    "data": {"n_states": 300},
    "teacher": {"n_candidates": 8, "n_iters": 1, "n_refine": 1},
    "model": {"hidden": [8]},
    "optim": {"max_epochs": 1, "batch_size": 256},
    "dagger": {"rounds": 0},
    "export_onnx": False,
}


def _libsumo() -> bool:
    from safelane.integrations.sumo_world import libsumo_available

    return libsumo_available()


#: Every command that writes a run folder, at the smallest sizes it takes (no mocks: the real commands run).
WRITING = {
    "simulate": ["--planner", "CV_none", "--leaders", "1", "--decel", "4", "--samples", "3", "--no-progress"],
    "falsify": ["--minutes", "0", "--scenarios", "4", "--batch-size", "8", "--method", "random", "--no-progress"],
    "reproduce": ["--quick", "--only", "fig5_example", "--no-progress"],  # one traced scenario
    "calibrate": ["--candidates", "1", "--samples", "1", "--refine", "0", "--finalists", "1", "--final-samples", "1"],
    "train": ["--no-progress"],  # + --config TINY_TRAIN (written per test)
    "sumo": ["--leaders", "1", "--decel", "4", "--episodes", "1", "--no-progress"],
    "replay": ["--connected", "0", "--no-progress"],  # the shipped sample
    "traffic": ["--penetration", "0", "--demand", "1000", "--seconds", "20", "--warmup", "10", "--no-progress"],
}
#: Commands with an ``--out`` that is not a run folder, and why.
NOT_A_RUN = {"export-onnx": "--out is the one .onnx file the user names"}


def _digest(folder) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}  # fmt: skip


def test_the_list_covers_every_command_with_an_out_folder():
    import typer.main

    group = typer.main.get_command(app)
    with_out = {name for name, cmd in group.commands.items() if any(p.name == "out" for p in cmd.params)}
    assert with_out == set(WRITING) | set(NOT_A_RUN)


@pytest.mark.parametrize("command", list(WRITING))
def test_every_writing_command_keeps_the_run_folder_contract(command, tmp_path):
    if command == "train":
        pytest.importorskip("torch")
    if command in ("sumo", "traffic") and not _libsumo():
        pytest.skip("libsumo is not installed: pip install 'safelane[sumo]'")
    args = [command, *WRITING[command], "--out", str(tmp_path / "out")]
    if command == "train":
        (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(TINY_TRAIN))
        args += ["--config", str(tmp_path / "tiny.yaml")]
    first = runner.invoke(app, args)
    assert first.exit_code == 0, first.output
    (run1,) = (tmp_path / "out").iterdir()
    before = _digest(run1)
    second = runner.invoke(app, args)
    assert second.exit_code == 0, second.output
    runs = sorted((tmp_path / "out").iterdir())
    assert len(runs) == 2, runs  # a new folder, not the old one again
    assert _digest(run1) == before  # the earlier run is untouched
    for run in runs:
        info = json.loads((run / "run.json").read_text(encoding="utf-8"))
        assert info["status"] == "complete"
        assert info["kind"] == command and info["run_id"] == run.name
        assert info["command"].startswith(f"safelane {command}")
        assert info["started_utc"] <= info["finished_utc"]
        assert {"python", "safelane", "numpy"} <= set(info["versions"])
        assert len([p for p in run.iterdir() if p.name != "run.json"]) >= 1  # and what the run made
