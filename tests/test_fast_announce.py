"""The first run's compilation is announced: once per process, only where a kernel module has no cached kernel."""

from __future__ import annotations

import io

import pytest

from test_fast_core import needs_numba

pytestmark = needs_numba


def test_compilation_is_announced_once_and_only_without_a_cache(tmp_path, monkeypatch):
    from safelane.safety import _fast_base

    monkeypatch.setattr(_fast_base, "_ANNOUNCED", [])
    monkeypatch.setattr(_fast_base.numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(_fast_base.numba.config, "DISABLE_JIT", 0)
    cached, fresh = tmp_path / "_fast_cached.py", tmp_path / "_fast_fresh.py"
    (tmp_path / "__pycache__").mkdir()
    (tmp_path / "__pycache__" / "_fast_cached.kernel-12.py311.nbi").write_bytes(b"")
    out = io.StringIO()
    assert not _fast_base.announce_compile(str(cached), out) and out.getvalue() == ""
    assert _fast_base.announce_compile(str(fresh), out)
    assert "compiling the numba kernels on first use" in out.getvalue() and "once" in out.getvalue()
    assert not _fast_base.announce_compile(str(fresh), out)  # said once per process
    assert out.getvalue().count("compiling") == 1


@pytest.mark.parametrize("setting", [("DISABLE_JIT", 1), ("CACHE_DIR", "/elsewhere")])
def test_nothing_is_announced_where_nothing_compiles_here(tmp_path, monkeypatch, setting):
    from safelane.safety import _fast_base

    monkeypatch.setattr(_fast_base, "_ANNOUNCED", [])
    monkeypatch.setattr(_fast_base.numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(_fast_base.numba.config, "DISABLE_JIT", 0)
    monkeypatch.setattr(_fast_base.numba.config, *setting)
    out = io.StringIO()
    assert not _fast_base.announce_compile(str(tmp_path / "_fast_x.py"), out) and out.getvalue() == ""


def test_every_kernel_module_announces():
    from safelane.safety._fast_base import KERNEL_SOURCES

    kernel_modules = 0
    for source in KERNEL_SOURCES:
        text = source.read_text()
        if source.name == "_fast_base.py":  # (defines the kernel decorator and the announcement)
            continue
        if "cache=True" in text or "@kernel(" in text:  # numba.njit(..., cache=True) or _fast_base.kernel
            kernel_modules += 1
            assert "announce_compile(__file__)" in text, source.name
    assert kernel_modules >= 10
