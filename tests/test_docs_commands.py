"""Every command in README.md and docs/*.md runs, so a documented example cannot break silently.

The fenced blocks are extracted (tests/docs_blocks.py) and run as a user would run them, from a scratch folder
that links the repository's ``src``, ``benchmarks``, ``tools``, ``examples`` and ``.venv`` (so relative paths in
the docs resolve, and every output lands in the scratch folder), with ``.venv/bin`` first on ``PATH``:

* shell blocks line by line in ``bash``, in order (a later line may read what an earlier one wrote);
* Python blocks as one program in a subprocess.

Sizes are made small by the rewriting rules below, each written out with its reason; nothing else is changed.
Commands that cannot run in a test at all are listed in ``NOT_RUN`` with the reason. Every other command runs:
a new fenced command is run by default, and fails the test if it does not work. A command needing an extra that
is not installed skips, naming it. Nothing runs in parallel (the test machines' cores are shared).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from docs_blocks import KNOWN_LANGS, REPO, SHELL_LANGS, Block, all_blocks, normalize

# --------------------------------------------------------------------------------------------------------------
# Commands that are never run here, with the reason (normalized: comments stripped, blanks collapsed).
# --------------------------------------------------------------------------------------------------------------
_INSTALL = "installs packages from a package index: needs the network and changes the environment"
_LONG = "recorded output of a measurement that takes minutes (the block shows what it printed)"
_CLUSTER = "needs a Ray cluster at an address that exists only in the example"
_MUTATE = "mutation testing: tens of minutes, and it rewrites mutants/ (docs/testing.md)"
_BENCH = "a benchmark: minutes of CPU, and its numbers are timings, which tests do not assert"
NOT_RUN: dict[str, str] = {
    "make run": "creates .venv and runs the full reproduction: the whole set-up, not a test (CI runs `make test`)",
    "make test": "runs this very test suite",
    "make lint": "may rebuild .venv (the target depends on its install stamp); CI runs ruff itself",
    "make mutate": _MUTATE,
    "make mutate-ci": _MUTATE + "; CI's .ci/run runs it",
    ".venv/bin/pytest -m slow": "the long verification campaigns (tens of minutes)",
    ".venv/bin/python benchmarks/bench_safety.py": _BENCH,
    ".venv/bin/python benchmarks/bench_sim.py": _BENCH,
    ".venv/bin/python benchmarks/bench_env.py": _BENCH,
    ".venv/bin/python benchmarks/bench_rss.py": _BENCH,
    ".venv/bin/python benchmarks/bench_backends.py": _BENCH,
    ".venv/bin/python benchmarks/bench_core.py": _BENCH,
    ".venv/bin/python benchmarks/bench_commonroad_referee.py": _BENCH,
    ".venv/bin/python benchmarks/bench_traffic.py --sizes 100 1000 5000 --steps 50": _BENCH,
    ".venv/bin/python benchmarks/bench_traffic.py --live 2500 4900 --seconds 100 --warmup 100": _BENCH,
    "safelane traffic --penetration 0,0.25,0.5,0.75,1 --demand 4900 --seconds 3900 --warmup 300 --workers 2":
        "five simulated hours of SUMO with the shield in the loop (about 45 minutes of CPU; docs/traffic.md)",
    "safelane traffic --penetration 0,0.25,0.5,0.75,1 --demand 4900 --seconds 300 --warmup 60 --workers 1":
        "the results table's sweep (tens of minutes of CPU; docs/traffic.md); tests/test_traffic.py runs short cells",
    ".venv/bin/python benchmarks/bench_core.py --repeat 3": _BENCH,
    ".venv/bin/python benchmarks/bench_falsify.py --worlds paper realistic --rounds 4": _BENCH,
    ".venv/bin/python benchmarks/bench_core.py --repeat 5": _BENCH,
    ".venv/bin/python benchmarks/ray_cluster.py": "starts and stops a Ray head node (tens of seconds); " + _BENCH,
    ".venv/bin/python examples/ppo_shield.py": "PPO training: 320 s of CPU on two processes (tests/test_envs.py "
    "runs its smoke mode)",
    'pip install "safelane[gym]"': _INSTALL,
    'pip install "safelane[highway]"': _INSTALL,
    'pip install -e ".[rss]"': _INSTALL,
    "pip install .": _INSTALL,
    "pip install '.[train]'": _INSTALL,
    "pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu": _INSTALL,
    "safelane reproduce --backend ray --ray-address HOST:6379": _CLUSTER,
    "safelane reproduce --backend ray --ray-address HEAD_HOST:6379": _CLUSTER,
    "safelane calibrate --backend ray --ray-address HEAD_HOST:6379 --workers 64": _CLUSTER,
    "safelane reproduce --backend ray": "starts a local Ray instance (about 40 s before any work; "
    "tests/test_backends.py runs the Ray backend)",
    "safelane falsify --backend ray --workers 64 --minutes 30 --scenarios 100000000": "starts a local Ray instance "
    "with 64 tasks (tests/test_backends.py runs the Ray backend)",
    "ray start --head --port=6379 --num-cpus=16 --include-dashboard=false --disable-usage-stats": "starts a Ray "
    "head node that outlives the test on a fixed port",
    "ray start --address=HEAD_HOST:6379 --num-cpus=16": _CLUSTER,
    "ray start --head --port=38851 --num-cpus=2 --include-dashboard=false --disable-usage-stats "
    "--temp-dir=/tmp/slray-52khsg1y/r --block": "recorded output of benchmarks/ray_cluster.py, which runs it",
    "safelane falsify --minutes 10 --scenarios 1000000 --seed 0 --out /tmp/fz_final --no-progress": _LONG,
    "safelane falsify --world lanes --scenarios 150000 --minutes 0 --seed 1 --batch-size 2048": _LONG,
    "safelane falsify --world lanes --scenarios 1400000 --minutes 0 --seed 2 --batch-size 2048 --workers 2": _LONG,
    "safelane falsify --world lanes --scenarios 1400000 --minutes 0 --seed 3 --batch-size 2048 --workers 2": _LONG,
    "git checkout 68a1771 && safelane falsify --minutes 0 --scenarios 20000 --seed 0 --no-progress": "checks out "
    "an old commit: " + _LONG,
    "safelane falsify --world realistic --scenarios 1000000 --minutes 0 --seed 17 --workers 2 --batch-size 16384":
        _LONG,
    ".venv/bin/python tools/mutate.py run decide": _MUTATE,
    ".venv/bin/python tools/mutate.py run --equivalents decide": _MUTATE,
    ".venv/bin/python tools/mutate.py table --strict": "reads the verdicts that `make mutate` caches in mutants/ "
    "(not in a fresh clone)",
    ".venv/bin/python tools/mutate.py review decide": "records a human review of equivalent mutants in "
    "tools/mutate_equivalents (changes the repository)",
    "cd mutants/decide && ../../.venv/bin/mutmut show safelane.shield.decide.x_check_candidate__mutmut_87":
        "reads mutants/ written by `make mutate`",
}

# --------------------------------------------------------------------------------------------------------------
# Rewriting rules: (pattern, replacement, reason), applied in order with re.sub; {tiny_train} is filled in.
# --------------------------------------------------------------------------------------------------------------
SHELL_REWRITES: list[tuple[str, str, str]] = [
    # Synopses: optional parts written [--option value] are run with the option (the first alternative of a|b).
    (r"\[--gui\] ?", "", "--gui opens SUMO's window: no display in a test"),
    (r"\[(--[a-z-]+) (\w+)\|[^\]]*\]", r"\1 \2", "a choice a|b: the first alternative"),
    (r"\[[A-Z][A-Za-z_.]*\] ?", "", "an optional placeholder argument (MODEL.npz): its default"),
    (r"\[(--[a-z-]+(?: [^\]\[|]+)?)\]", r"\1", "an optional option: run with it"),
    # Sizes.
    (r"--samples \d+", "--samples 20", "scenarios per cell"),
    (r"^(safelane simulate(?!.*--samples).*)$", r"\1 --samples 20", "simulate's default of 1000 scenarios"),
    (r"--episodes \d+", "--episodes 2", "SUMO episodes (about a second each)"),
    (r"--minutes \d+", "--minutes 0", "falsify: no time budget, only the scenario count"),
    (r"--scenarios \d+", "--scenarios 64", "falsify: a few scenarios"),
    (r"^(safelane falsify(?!.*--replay)(?!.*--batch-size).*)$", r"\1 --batch-size 64",
     "falsify: small batches (the default generates 16,384 scenarios a batch)"),
    (r"^safelane reproduce(?!.*--quick)", "safelane reproduce --quick", "reproduce: the reduced grid"),
    (r"^(safelane reproduce(?!.*--only).*)$", r"\1 --only leaders",
     "reproduce: one experiment of the reduced grid (tests/test_reproduce.py runs every experiment)"),
    (r"^(safelane calibrate.*)$", r"\1 --candidates 2 --samples 5 --refine 0 --finalists 1 --final-samples 5",
     "calibrate: two candidates on 5 scenarios per cell (the default takes minutes)"),
    (r"--config src/safelane/models/default_train\.yaml", "--config {tiny_train}",
     "train: a config of about a second (tests/test_training.py's tiny config) instead of 4 minutes"),
    (r"--workers \d+", "--workers 1", "parallelise nothing (the test machines' cores are shared)"),
    (r"^(python benchmarks/(?:closed_loop_nn|supervisor_ablation)\.py.*)$", r"\1 --samples 20",
     "benchmark scripts of closed-loop success: 20 scenarios per cell"),
    (r"^(python benchmarks/supervisor_ablation\.py.*)$", r"\1 --random-nets 1", "one random network"),
    (r"(\S*)<run-id>(\S*)", r"$(ls -d \1*\2 | head -n 1)", "a run folder that a line before wrote"),
]
PYTHON_REWRITES: list[tuple[str, str, str]] = [
    (r"sumo_scenarios\((.*)samples=\d+", r"sumo_scenarios(\1samples=2", "SUMO episodes (about a second each)"),
    (r"samples=\d+", "samples=20", "scenarios per cell"),
    (r"num_envs=1024", "num_envs=16", "sub-environments of the vector env"),
    (r"<run-id>", "run0", "a run folder the test writes first: the shipped model and its ONNX export"),
]

# An extra the command needs (its import name): the command skips, saying so, where it is not installed.
EXTRAS: list[tuple[str, tuple[str, ...]]] = [
    (r"safelane sumo|SumoRunner", ("libsumo",)),
    (r"safelane train", ("torch",)),
    (r"export-onnx|from_onnx", ("onnx", "onnxruntime")),
    (r"highway", ("gymnasium", "highway_env")),
    (r"gymnasium|gym\.", ("gymnasium",)),
    (r"integrations\.commonroad", ("commonroad", "commonroad_dc")),
]

TIMEOUT_S = 240


def rewrite(command: str, rules, **fill: str) -> str:
    for pattern, replacement, _why in rules:
        command = re.sub(pattern, replacement.format(**fill) if fill else replacement, command, flags=re.M)
    return command


def missing_extras(text: str) -> list[str]:
    return [m for pattern, mods in EXTRAS if re.search(pattern, text) for m in mods
            if importlib.util.find_spec(m) is None]


BLOCKS = [b for b in all_blocks()
          if b.lang == "python" or (b.lang in SHELL_LANGS and any(c not in NOT_RUN for c in b.commands()))]


@pytest.fixture
def workdir(tmp_path: Path) -> Path:
    """A scratch folder a user could have cloned into: the repository's code linked in, outputs local."""
    for name in ("src", "benchmarks", "tools", "examples", ".venv"):
        if (REPO / name).exists():
            (tmp_path / name).symlink_to(REPO / name)
    (tmp_path / "p.yaml").write_text("p_m: 5.0\n")  # for simulator.md's `--params p.yaml`
    tiny = {"seed": 0, "data": {"n_states": 1500}, "teacher": {"n_candidates": 16, "n_iters": 2, "n_refine": 2},
            "model": {"hidden": [16, 16]}, "optim": {"max_epochs": 4, "batch_size": 256}}
    (tmp_path / "tiny_train.yaml").write_text(yaml.safe_dump(tiny))
    return tmp_path


def _env(workdir: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["SAFELANE_PRESET_DIR"] = str(workdir / "presets")  # calibrate --install writes here, not to ~/.config
    env["MPLBACKEND"] = "Agg"
    env["PYTHONWARNINGS"] = "ignore::DeprecationWarning"
    env.pop("RAY_ADDRESS", None)
    return env


def _run(args: list[str], workdir: Path, what: str) -> None:
    proc = subprocess.run(args, cwd=workdir, env=_env(workdir), capture_output=True, text=True, timeout=TIMEOUT_S)
    assert proc.returncode == 0, f"{what}\nexit {proc.returncode}\n--- stdout\n{proc.stdout[-3000:]}\n" \
                                 f"--- stderr\n{proc.stderr[-3000:]}"


def _prepare_trained_run(workdir: Path) -> None:
    """results/mlp/run0/model.npz and model.onnx, as `safelane train --out results/mlp` would leave them."""
    run = workdir / "results" / "mlp" / "run0"
    run.mkdir(parents=True)
    shutil.copy(REPO / "src" / "safelane" / "models" / "mlp_default.npz", run / "model.npz")
    _run(["safelane", "export-onnx", str(run / "model.npz"), "--out", str(run / "model.onnx")], workdir,
         "preparing results/mlp/run0/model.onnx")


@pytest.mark.parametrize("block", BLOCKS, ids=[b.where for b in BLOCKS])
def test_documented_block_runs(block: Block, workdir: Path) -> None:
    if block.lang == "python":
        if missing := missing_extras(block.text):
            pytest.skip(f"{block.where} needs {', '.join(missing)} (not installed)")
        source = rewrite(block.text, PYTHON_REWRITES)
        if "run0" in source:
            _prepare_trained_run(workdir)
        _run([sys.executable, "-c", source], workdir, f"{block.where}: the Python block, as run:\n{source}")
        return
    for command in block.commands():
        if command in NOT_RUN:
            continue
        if missing := missing_extras(command):
            pytest.skip(f"{block.where}: `{command}` needs {', '.join(missing)} (not installed)")
        as_run = rewrite(command, SHELL_REWRITES, tiny_train="tiny_train.yaml")
        _run(["bash", "-c", as_run], workdir, f"{block.where}: `{command}`, run as `{as_run}`")


def test_every_fenced_block_is_classified() -> None:
    """A block tagged with an unknown language is neither run nor recognised as output: tag it."""
    unknown = [f"{b.where} ```{b.lang}" for b in all_blocks() if b.lang not in KNOWN_LANGS]
    assert not unknown, f"fenced blocks with a language this test does not know: {unknown}"


def test_every_recorded_command_is_listed() -> None:
    """A `$ command` line in an output block is documentation of a run: it must be listed with its reason (or
    moved to a bash block, where it runs)."""
    recorded = [(b.where, c) for b in all_blocks() if b.lang not in SHELL_LANGS for c in b.commands()]
    unlisted = [f"{where}: {c}" for where, c in recorded if c not in NOT_RUN]
    assert not unlisted, "recorded commands neither run nor listed in NOT_RUN:\n" + "\n".join(unlisted)


def test_not_run_list_has_no_stale_entries() -> None:
    documented = {c for b in all_blocks() for c in b.commands()}
    stale = sorted(set(NOT_RUN) - documented)
    assert not stale, f"NOT_RUN lists commands no longer in the docs: {stale}"


def test_every_rewriting_rule_is_used() -> None:
    """A rule that no documented command needs any more is removed, so the list says what is changed."""
    shell = [c for b in all_blocks() if b.lang in SHELL_LANGS for c in b.commands() if c not in NOT_RUN]
    python = [b.text for b in all_blocks() if b.lang == "python"]
    unused = [p for p, _, _ in SHELL_REWRITES if not any(re.search(p, c, flags=re.M) for c in shell)]
    unused += [p for p, _, _ in PYTHON_REWRITES if not any(re.search(p, t, flags=re.M) for t in python)]
    assert not unused, f"rewriting rules no documented command uses: {unused}"


def test_rewrites_keep_the_command() -> None:
    """The rules only shrink sizes and fill in synopses: the program and its subcommand stay the same."""
    for b in all_blocks():
        if b.lang not in SHELL_LANGS:
            continue
        for c in b.commands():
            if c in NOT_RUN:
                continue
            as_run = rewrite(c, SHELL_REWRITES, tiny_train="tiny_train.yaml")
            assert as_run.split()[:2] == c.split()[:2], (c, as_run)
            assert "[" not in as_run and not re.search(r"\w\|\w", as_run), f"{b.where}: a synopsis left: {as_run}"


def test_normalize_is_what_not_run_uses() -> None:
    assert all(normalize(c) == c for c in NOT_RUN)
