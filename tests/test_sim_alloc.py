"""The allocator tuning: applied once, opt-out honoured, results unchanged by it."""

from __future__ import annotations

import os
import subprocess
import sys

import pandas as pd
import pytest

from safelane.sim import _alloc, simulate


def test_opt_out_is_honoured(monkeypatch):
    monkeypatch.setenv("SAFELANE_MALLOC_TUNING", "0")
    assert _alloc._apply() is False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_glibc_accepts_the_settings(monkeypatch):
    monkeypatch.delenv("SAFELANE_MALLOC_TUNING", raising=False)
    assert _alloc._apply() is True
    monkeypatch.setattr(_alloc, "_applied", None)
    assert _alloc.tune_allocator() is True and _alloc.tune_allocator() is True  # once, then remembered


def test_results_do_not_depend_on_the_allocator(tmp_path):
    """The same cell in a fresh process with the tuning off, and here (tuning on): the same table."""
    script = (
        "from safelane.sim import simulate; "
        f"simulate('CV_all', n_leaders=3, decel=6.0, samples=64, seed=5).table.to_pickle({str(tmp_path / 'off.pkl')!r})"
    )
    env = {**os.environ, "SAFELANE_MALLOC_TUNING": "0"}
    subprocess.run([sys.executable, "-c", script], check=True, env=env)
    tuned = simulate("CV_all", n_leaders=3, decel=6.0, samples=64, seed=5).table
    assert _alloc.tune_allocator() is sys.platform.startswith("linux")
    assert tuned.equals(pd.read_pickle(tmp_path / "off.pkl"))
