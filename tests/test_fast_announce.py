"""The first run's compilation is announced: once per process, only where numba really compiles one of safelane's
functions (its ``numba:compile`` event, which a load from the cache does not fire)."""

from __future__ import annotations

import io

import pytest

from test_fast_core import needs_numba

pytestmark = needs_numba


def _quiet(monkeypatch, _fast_base):
    monkeypatch.setattr(_fast_base, "_ANNOUNCED", [])
    monkeypatch.setattr(_fast_base.numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(_fast_base.numba.config, "DISABLE_JIT", 0)


def test_compilation_is_announced_once(monkeypatch):
    from safelane.safety import _fast_base

    _quiet(monkeypatch, _fast_base)
    out = io.StringIO()
    assert _fast_base.say_compiling(out)
    assert "compiling the numba kernels on first use" in out.getvalue() and "once" in out.getvalue()
    assert not _fast_base.say_compiling(out)  # said once per process
    assert out.getvalue().count("compiling") == 1


@pytest.mark.parametrize("setting", [("DISABLE_JIT", 1), ("CACHE_DIR", "/elsewhere")])
def test_nothing_is_announced_where_nothing_compiles_here(monkeypatch, setting):
    from safelane.safety import _fast_base

    _quiet(monkeypatch, _fast_base)
    monkeypatch.setattr(_fast_base.numba.config, *setting)
    out = io.StringIO()
    assert not _fast_base.say_compiling(out) and out.getvalue() == ""


def test_the_listener_speaks_for_safelane_functions_only(monkeypatch):
    from types import SimpleNamespace

    from safelane.safety import _fast_base

    _quiet(monkeypatch, _fast_base)
    spoken = []
    monkeypatch.setattr(_fast_base, "say_compiling", lambda stream=None: spoken.append(True))
    listener = _fast_base._CompileListener()
    other = SimpleNamespace(data={"dispatcher": SimpleNamespace(py_func=SimpleNamespace(__module__="numpy.x"))})
    ours = SimpleNamespace(data={"dispatcher": SimpleNamespace(py_func=SimpleNamespace(__module__="safelane.sim.x"))})
    listener.on_start(other)
    listener.on_start(SimpleNamespace(data=None))
    listener.on_start(SimpleNamespace(data={"dispatcher": SimpleNamespace(py_func=SimpleNamespace(__module__=None))}))
    assert spoken == []
    listener.on_start(ours)
    assert spoken == [True]


def test_a_real_compile_of_a_safelane_function_is_announced(monkeypatch):
    """numba's ``numba:compile`` event reaches the listener when a function of safelane is compiled (a load from the
    cache does not fire it: numba triggers the event after a cache miss only)."""
    import numba

    from safelane.safety import _fast_base

    _fast_base.announce_compiles()
    spoken = []
    monkeypatch.setattr(_fast_base, "say_compiling", lambda stream=None: spoken.append(True))
    namespace = {"__name__": "safelane.fake_kernels"}
    exec("def twice(x):\n    return 2.0 * x\n", namespace)
    assert numba.njit(namespace["twice"])(2.0) == 4.0
    assert spoken
    spoken.clear()
    namespace = {"__name__": "elsewhere"}
    exec("def thrice(x):\n    return 3.0 * x\n", namespace)
    assert numba.njit(namespace["thrice"])(2.0) == 6.0
    assert not spoken


def test_every_kernel_module_announces():
    from safelane.safety._fast_base import KERNEL_SOURCES

    kernel_modules = 0
    for source in KERNEL_SOURCES:
        text = source.read_text()
        if source.name == "_fast_base.py":  # (defines the kernel decorator and the announcement)
            continue
        if "cache=True" in text or "@kernel(" in text:  # numba.njit(..., cache=True) or _fast_base.kernel
            kernel_modules += 1
            assert "announce_compiles()" in text, source.name
    assert kernel_modules >= 10
