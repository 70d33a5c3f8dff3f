"""The compiled monitor (:mod:`safelane.shield._fast_monitor`, numba) against ``monitor.observe_breaches``' NumPy path:
the same flags and first-breach times on ``test_monitor_unit``'s snapshots with observations at and around
``TOL_M`` of every assumed worst case, with a previous record, when the chain changed length, and with NaN and
infinite limits; the closed loop's table with breaches (unexpected promise violations) is the same with and without
it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.shield import monitor
from safelane.shield.monitor import BREACH_KINDS, Breach, observe_breaches, predicted_positions
from test_fast_core import needs_numba, period_by_period  # noqa: F401 (a fixture)
from test_monitor_unit import OFFSETS, _snapshot

pytestmark = [pytest.mark.compiled, pytest.mark.usefixtures("period_by_period")]

PRM = Params()


def _both(monkeypatch, prev, last, situation, t):
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = observe_breaches(prev, last, situation, PRM, t)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    slow = observe_breaches(prev, last, situation, PRM, t)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    np.testing.assert_array_equal(fast.flags, slow.flags)
    np.testing.assert_array_equal(fast.first_s, slow.first_s)
    return slow


@needs_numba
@pytest.mark.parametrize("m", [1, 4, 11])
def test_the_kernel_gives_the_numpy_paths_flags(monkeypatch, m):
    rng = np.random.default_rng(m)
    b = 3000
    last = _snapshot(rng, b, m)
    last.f_limit[rng.random(b) < 0.05] = np.nan  # NaN and -inf limits: not watched / compared as NumPy does
    last.f_limit[rng.random(b) < 0.05] = -np.inf
    tx, fx = predicted_positions(last, PRM.dt)
    new_x = tx + rng.choice(OFFSETS, (b, m))
    l1 = rng.random(b) < 0.5
    new_x[l1, 0] = new_x[l1, 0] - rng.choice(OFFSETS, l1.sum())
    new_f = fx - rng.choice(OFFSETS, b)
    prev_flags = np.zeros((b, len(BREACH_KINDS)), bool)
    had = rng.random(b) < 0.3
    prev_flags[had, rng.integers(0, len(BREACH_KINDS), had.sum())] = True
    prev = Breach(flags=prev_flags, first_s=np.where(had, 1.0, np.nan))
    out = _both(monkeypatch, prev, last, SimpleNamespace(chain_x=new_x, f_x=new_f), 2.5)
    fresh = out.flags & ~prev_flags
    for col in range(4) if m > 1 else (0, 2, 3):  # every kind newly seen, and not everywhere (L1 alone: no link)
        assert 0 < fresh[:, col].sum() < b
    # the chain changed length: only F is compared
    _both(monkeypatch, prev, last, SimpleNamespace(chain_x=new_x[:, :-1] - 50.0, f_x=new_f), 2.5)


@needs_numba
def test_the_kernel_runs_from_its_threshold_and_not_below_or_with_the_switch(monkeypatch):
    from safelane.shield import _fast_monitor

    calls = []
    real = _fast_monitor.observe_breaches
    monkeypatch.setattr(_fast_monitor, "observe_breaches", lambda *a: calls.append(len(a[0].first_s)) or real(*a))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    for rows in (monitor.FAST_MIN_ROWS - 1, monitor.FAST_MIN_ROWS):
        last = _snapshot(np.random.default_rng(rows), rows, 3)
        observe_breaches(Breach.none(rows), last, SimpleNamespace(chain_x=last.chain_x, f_x=last.f_x), PRM, 1.0)
    assert calls == [monitor.FAST_MIN_ROWS]
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    last = _snapshot(np.random.default_rng(2), 500, 3)
    observe_breaches(Breach.none(500), last, SimpleNamespace(chain_x=last.chain_x, f_x=last.f_x), PRM, 1.0)
    assert len(calls) == 1


@needs_numba
def test_the_closed_loop_records_the_same_breaches_with_and_without_the_kernel(monkeypatch):
    from safelane.sim import SimConfig, paper_scenarios, simulate_batch

    batch = paper_scenarios("CV_all", 3, 6.0, 300, np.random.default_rng(5), p_v=0.1)
    cfg = SimConfig(follower_ignores_ego=True)  # F breaks the follower assumption as well
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = simulate_batch(batch, seed=6, config=cfg).table
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = simulate_batch(batch, seed=6, config=cfg).table
    assert fast.equals(reference)
    breach_cols = [c for c in reference.columns if c.startswith("breach")]
    assert breach_cols and reference[breach_cols].to_numpy().any()
