"""The compiled evasion kernel (:mod:`safelane.safety._fast`, numba) against the NumPy path it accelerates.

The NumPy path (``evasion_core``) is the reference. The kernel must give the same verdicts and — checked here on
its ``gaps`` output — the same leader and follower gaps, bit for bit, on random states (``test_safety_shapes``'s
sampler, with its exact boundary values) and on knife edges: gaps exactly at the margin, equal speeds, ``L1``
braking at ``a_x_d`` (equal decelerations), stopped vehicles, the ego exactly on ``y_s``, a lateral return that
lands exactly on ``y_s``. ``SAFELANE_NO_NUMBA=1`` must keep the NumPy path. The kernel tests skip where numba is
missing (``pip install 'safelane[fast]'``; ``make install`` installs it, so CI runs them).
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from safelane import Params
from safelane.safety import evasion as ev
from safelane.safety import evasion_exists
from safelane.safety._backend import ARRAY, FEASIBILITY_TOL_M
from safelane.safety.lateral import LATERAL_TOL_M
from test_safety_shapes import evasion_inputs

# A compiled kernel against the uncompiled path (tests/conftest.py: skipped while mutation testing mutates them).
pytestmark = pytest.mark.compiled

PARAMS = Params()
HAS_NUMBA = importlib.util.find_spec("numba") is not None
needs_numba = pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed (extra 'fast'): no kernel to compare")


@pytest.fixture
def period_by_period(monkeypatch):
    """The closed loop period by period (``SAFELANE_NO_FUSED=1``), so that a simulation runs the part kernels a test
    is about rather than the compiled loop (``sim/_fast_loop.py``), which covers the default settings."""
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")


def knife_edges(rng: np.random.Generator, n: int) -> dict:
    """``n`` states on the boundaries where the closed forms switch case or a gap sits exactly at its margin."""
    prm = PARAMS
    s = evasion_inputs(rng, (n,))
    pick = lambda p: rng.random(n) < p  # noqa: E731
    v = rng.choice([0.0, 5.0, 20.0, 27.5, 35.0], n)
    # equal speeds: ego, L1 and F at the same speed (a fraction of each)
    for key in ("ego_vx", "l1_v", "f_v"):
        s[key] = np.where(pick(0.5), v, s[key])
    # slack exactly 0: L1 or F exactly p_m (or p_m_human) from the ego
    s["ego_px"] = np.where(pick(0.5), 0.0, s["ego_px"])
    lead_margin = np.where(pick(0.5), prm.p_m, prm.p_m_human)
    s["l1_p"] = np.where(pick(0.4), s["ego_px"] + lead_margin, s["l1_p"])
    s["f_p"] = np.where(pick(0.4), s["ego_px"] - rng.choice([prm.p_m, prm.p_m_human], n), s["f_p"])
    # L1 braking at a_x_d (the ego's deceleration: no relative deceleration), or not at all
    s["l1_decel"] = np.where(pick(0.3), prm.a_x_d, np.where(pick(0.15), 0.0, s["l1_decel"]))
    # lateral: on y_s, within the tolerance of it, or returning so that it stops exactly on it
    vy = s["ego_vy"]
    stops_on = prm.y_safe + vy * np.abs(vy) / (2.0 * prm.a_y_m)  # e = -v_y|v_y|/(2a): s = 0
    py = np.where(pick(0.2), prm.y_safe, s["ego_py"])
    py = np.where(pick(0.1), prm.y_safe + LATERAL_TOL_M, py)
    py = np.where(pick(0.1) & (vy < 0.0), stops_on, py)
    s["ego_py"] = py
    s["ego_vy"] = np.where(pick(0.1), 0.0, vy)
    return s


def _inputs(states: dict, human: tuple) -> tuple:
    return ev._prepare_evasion(*(states[k] for k in ev._PLAN_INPUTS), states["follower_aggressive"], PARAMS, *human)[1]


def _same_bits(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a == b) | (np.isnan(a) & np.isnan(b))


def _cases(seed: int = 13, n: int = 40_000):
    """Random states, knife edges with human-driven margins, knife edges at ``p_m``: ``(name, states, human)``."""
    rng = np.random.default_rng(seed)
    humans = (rng.random(n) < 0.3, rng.random(n) < 0.3)
    return [
        ("random", evasion_inputs(rng, (n,)), humans),
        ("knife edges", knife_edges(rng, n), humans),
        ("knife edges, p_m everywhere", knife_edges(rng, n), (False, False)),
    ]


@needs_numba
@pytest.mark.parametrize("name,states,human", _cases(), ids=lambda x: x if isinstance(x, str) else "")
def test_kernel_gives_the_numpy_paths_bits(name, states, human, monkeypatch):
    from safelane.safety import _fast

    args = _inputs(states, human)
    n = len(states["ego_px"])
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")  # evasion_core itself would run the plan kernel (_fast.plan_kernel)
    with np.errstate(all="ignore"):
        exists, parts = ev.evasion_core(ARRAY, *args, PARAMS)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    fast, gaps = _fast.run(args, (n,), PARAMS, FEASIBILITY_TOL_M, want_gaps=True)
    np.testing.assert_array_equal(fast, exists, err_msg=name)
    for row, key in enumerate(("lead_gap", "follow_gap")):
        same = _same_bits(gaps[row], parts[key])
        assert same.all(), f"{name}: {key} differs at {np.flatnonzero(~same)[:5]}"
    # the verdict-only mode (early exits) and the chunked NumPy path the public function takes
    np.testing.assert_array_equal(_fast.run(args, (n,), PARAMS, FEASIBILITY_TOL_M), exists)
    np.testing.assert_array_equal(ev._exists_chunked(args, (n,), PARAMS), exists)
    # both verdicts occur, and on the knife edges many gaps sit within the tolerance of the margin
    assert 0.05 < exists.mean() < 0.95
    if "knife" in name:
        assert (np.abs(parts["lead_gap"]) <= FEASIBILITY_TOL_M).sum() > 100


@needs_numba
def test_public_function_dispatches_and_agrees(monkeypatch):
    from safelane.safety import _fast

    rng = np.random.default_rng(14)
    shape = (64, 128)  # >= FAST_MIN_BATCH elements, two dimensions, some inputs broadcast from scalars
    s = knife_edges(rng, 64 * 128)
    s = {k: v.reshape(shape) for k, v in s.items()}
    s["ego_px"] = 0.0
    s["l1_decel"] = np.broadcast_to(PARAMS.a_x_d, shape)  # a read-only view
    calls = []
    real = _fast.run
    monkeypatch.setattr(_fast, "run", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    for human in (False, True):
        fast = evasion_exists(**s, params=PARAMS, leader_human=human, follower_human=human)
        monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
        reference = evasion_exists(**s, params=PARAMS, leader_human=human, follower_human=human)
        monkeypatch.delenv("SAFELANE_NO_NUMBA")
        assert fast.shape == shape and fast.dtype == np.bool_
        np.testing.assert_array_equal(fast, reference)
    assert len(calls) == 2  # the kernel ran for the two calls without the switch, and only for those


@needs_numba
def test_small_batches_take_the_numpy_path(monkeypatch):
    from safelane.safety import _fast

    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.setattr(_fast, "run", lambda *a, **k: pytest.fail("the kernel ran for a small batch"))
    s = evasion_inputs(np.random.default_rng(15), (ev.FAST_MIN_BATCH - 1,))
    assert evasion_exists(**s, params=PARAMS).shape == (ev.FAST_MIN_BATCH - 1,)


def test_env_switch_forces_the_numpy_path(monkeypatch):
    # runs with or without numba: the switch means the kernel module is never asked for
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    assert ev.fast_kernel() is None
    s = evasion_inputs(np.random.default_rng(16), (ev.FAST_MIN_BATCH,))
    args = _inputs(s, (False, False))
    np.testing.assert_array_equal(
        evasion_exists(**s, params=PARAMS), ev._exists_chunked(args, (ev.FAST_MIN_BATCH,), PARAMS)
    )


def test_without_numba_the_numpy_path_answers(monkeypatch):
    # numba failing to import (not installed) leaves the NumPy path, tried once per process
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.setattr(ev, "_FAST", [None])
    assert ev.fast_kernel() is None
    s = evasion_inputs(np.random.default_rng(17), (ev.FAST_MIN_BATCH,))
    assert evasion_exists(**s, params=PARAMS).shape == (ev.FAST_MIN_BATCH,)


@needs_numba
def test_an_edited_kernel_source_drops_every_kernels_cache(tmp_path):
    # numba keys a cached kernel on its own file only; helpers from another kernel file are compiled into it
    from safelane.safety._fast_base import KERNEL_SOURCES, drop_stale_caches

    names = {p.name for p in KERNEL_SOURCES}
    assert {"_fast.py", "_fast_decide.py", "_fast_monitor.py", "_fast_traffic.py"} <= names
    helper, kernel = tmp_path / "_fast_helper.py", tmp_path / "_fast_kernel.py"
    helper.write_text("x = 1\n")
    kernel.write_text("y = 2\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    cached = [cache / "_fast_kernel.k-10.py311.nbi", cache / "_fast_kernel.k-10.py311.1.nbc"]
    other = cache / "_fast_kernel.cpython-311.pyc"

    def fill():
        for path in (*cached, other):
            path.write_bytes(b"")

    stamp = tmp_path / "stamp"
    fill()
    assert drop_stale_caches((helper, kernel), stamp)  # no stamp yet: dropped
    assert not any(p.exists() for p in cached) and other.exists()
    fill()
    assert not drop_stale_caches((helper, kernel), stamp)  # nothing changed: kept
    assert all(p.exists() for p in cached)
    helper.write_text("x = 3\n")  # the helper's file changed, not the kernel's: the kernel's cache goes
    assert drop_stale_caches((helper, kernel), stamp)
    assert not any(p.exists() for p in cached) and other.exists()
