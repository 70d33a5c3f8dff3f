"""The dispatch of :func:`safelane.safety.evasion_exists` between the NumPy path and the compiled kernel
(``safelane.safety._fast``), as its docstring states it: NumPy batches of ``FAST_MIN_BATCH`` elements or more go to
the kernel where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``; smaller batches, scalars, the switch and a
failed numba import keep the NumPy path; the kernel module is looked up once per process. The verdicts are the same
either way. (The kernel's bits against the NumPy path: ``tests/test_fast_core.py``.)"""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

import safelane.safety as safety_pkg
from safelane import Params
from safelane.safety import evasion as ev
from safelane.safety import evasion_exists
from test_safety_shapes import evasion_inputs

# A compiled kernel against the uncompiled path (tests/conftest.py: skipped while mutation testing mutates them).
pytestmark = pytest.mark.compiled

PARAMS = Params()
HAS_NUMBA = importlib.util.find_spec("numba") is not None
needs_numba = pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed (extra 'fast')")


def _counting(monkeypatch):
    """Count the kernel's runs (the real kernel still answers)."""
    from safelane.safety import _fast

    calls = []
    real = _fast.run
    monkeypatch.setattr(_fast, "run", lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    return calls


def _numpy_answer(monkeypatch, s, **kw):
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    out = evasion_exists(**s, params=PARAMS, **kw)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    return out


@needs_numba
@pytest.mark.parametrize("human", [False, True])
def test_a_batch_of_exactly_fast_min_batch_runs_the_kernel_and_agrees(monkeypatch, human):
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    calls = _counting(monkeypatch)
    s = evasion_inputs(np.random.default_rng(31), (ev.FAST_MIN_BATCH,))
    fast = evasion_exists(**s, params=PARAMS, leader_human=human, follower_human=human)
    assert calls == [(ev.FAST_MIN_BATCH,)]
    reference = _numpy_answer(monkeypatch, s, leader_human=human, follower_human=human)
    assert fast.shape == (ev.FAST_MIN_BATCH,) and fast.dtype == np.bool_
    np.testing.assert_array_equal(fast, reference)
    assert 0.05 < fast.mean() < 0.95


@needs_numba
def test_scalars_and_small_batches_never_run_the_kernel(monkeypatch):
    from safelane.safety import _fast

    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.setattr(_fast, "run", lambda *a, **k: pytest.fail("the kernel ran"))
    s = evasion_inputs(np.random.default_rng(32), (8,))
    for i in range(8):
        one = {k: (v[i].item() if isinstance(v, np.ndarray) else v) for k, v in s.items()}
        got = evasion_exists(**one, params=PARAMS)
        assert isinstance(got, np.bool_ | bool)
        assert bool(got) == bool(_numpy_answer(monkeypatch, one))
    # and a NumPy batch one element short of the threshold
    small = evasion_inputs(np.random.default_rng(33), (ev.FAST_MIN_BATCH - 1,))
    np.testing.assert_array_equal(evasion_exists(**small, params=PARAMS), _numpy_answer(monkeypatch, small))


@needs_numba
def test_the_kernel_module_is_looked_up_once(monkeypatch):
    from safelane.safety import _fast

    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.setattr(ev, "_FAST", [])
    assert ev.fast_kernel() is _fast
    assert ev._FAST == [_fast]
    assert ev.fast_kernel() is _fast and ev._FAST == [_fast]
    # The switch wins over the cached module.
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    assert ev.fast_kernel() is None
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "0")
    assert ev.fast_kernel() is _fast


def test_a_failed_numba_import_leaves_the_numpy_path(monkeypatch):
    """The kernel module failing to import (numba missing) is remembered as ``None``."""
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.setattr(ev, "_FAST", [])
    monkeypatch.delattr(safety_pkg, "_fast", raising=False)
    monkeypatch.setitem(sys.modules, "safelane.safety._fast", None)  # `from . import _fast` raises ImportError
    assert ev.fast_kernel() is None
    assert ev._FAST == [None]
    s = evasion_inputs(np.random.default_rng(33), (ev.FAST_MIN_BATCH,))
    got = evasion_exists(**s, params=PARAMS)
    np.testing.assert_array_equal(got, _numpy_answer(monkeypatch, s))


def test_the_switch_keeps_the_numpy_path_without_asking_for_the_module(monkeypatch):
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    monkeypatch.setattr(ev, "_FAST", [])
    assert ev.fast_kernel() is None
    assert ev._FAST == []
