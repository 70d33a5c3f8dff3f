"""`make run` installs only what the reproduction needs; `make test` the rest, with PyTorch's CPU build pinned so
that no index can substitute the CUDA-bundled wheels; the docs say how to get the CPU build anywhere.

The Makefile is read with `make -n` (prints the commands, runs nothing) in a scratch copy without a .venv, i.e. as
on a fresh clone.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from docs_blocks import REPO

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")


def _dry_run(tmp_path: Path, target: str, *args: str) -> list[str]:
    for name in ("Makefile", "pyproject.toml"):
        shutil.copy(REPO / name, tmp_path / name)
    out = subprocess.run(["make", "-n", target, *args], cwd=tmp_path, capture_output=True, text=True, check=True)
    return [line for line in out.stdout.splitlines() if "pip install" in line]


def _extras(lines: list[str]) -> set[str]:
    found = set()
    for line in lines:
        for group in re.findall(r'-e "\.\[([^\]]*)\]"', line):
            found |= set(group.split(","))
    return found


def test_make_run_installs_only_what_the_reproduction_needs(tmp_path):
    lines = _dry_run(tmp_path, "run")
    assert lines, "make run installs nothing?"
    assert not any("torch" in line for line in lines), lines
    assert _extras(lines) <= {"fast"}, f"make run installs extras it does not need: {_extras(lines) - {'fast'}}"


def test_make_test_pins_the_cpu_build_of_pytorch(tmp_path):
    lines = _dry_run(tmp_path, "test")
    torch = [line for line in lines if "torch" in line]
    assert torch, "make test must install PyTorch (extra train) before the rest"
    # A bare `torch==X` resolves to the CUDA-bundled wheels on PyPI; the local version `+cpu` cannot.
    assert all(re.search(r"torch==[\d.]+\+cpu", line) for line in torch), torch
    assert {"dev", "train", "gym", "rl", "highway"} <= _extras(lines)
    assert lines.index(torch[0]) < next(i for i, line in enumerate(lines) if "train" in line)
    with_index = [line for line in _dry_run(tmp_path, "test", "TORCH_INDEX_URL=https://example.invalid/cpu")
                  if "torch" in line]
    assert any("--extra-index-url https://example.invalid/cpu" in line for line in with_index), with_index


def test_the_docs_say_how_to_get_the_cpu_build_anywhere():
    usage = (REPO / "docs" / "usage.md").read_text(encoding="utf-8")
    assert re.search(r"pip install torch==[\d.]+ --index-url https://download\.pytorch\.org/whl/cpu", usage)
    assert "TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu" in usage
    makefile = (REPO / "Makefile").read_text(encoding="utf-8")
    pinned = re.search(r"torch==([\d.]+)\+cpu", makefile).group(1)
    assert f"torch=={pinned} --index-url" in usage, "docs/usage.md and the Makefile pin different PyTorch versions"


def test_the_reproduction_runs_without_the_test_only_packages(tmp_path):
    """What `make run` leaves out (PyTorch, stable-baselines3, Gymnasium, highway-env, Ray, SUMO, ONNX, the dev
    tools) is not imported by `safelane reproduce`: blocked here, a reduced run still completes."""
    blocked = ["torch", "stable_baselines3", "gymnasium", "highway_env", "ray", "libsumo", "traci", "onnx",
               "onnxruntime", "scipy", "hypothesis", "pytest", "ad_rss"]
    code = (
        "import sys\n"
        f"for name in {blocked!r}:\n"
        "    sys.modules[name] = None  # import fails, as where the package is not installed\n"
        "from safelane.cli import app\n"
        f"app(['reproduce', '--quick', '--only', 'table1', '--out', {str(tmp_path)!r}, '--no-progress'])\n"
    )
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert list(tmp_path.glob("*/report.md")), "no report written"
