"""The compiled leader rule (:mod:`safelane.sim._fast_traffic`, numba) against ``behaviours.leader_accels``' NumPy path.

The NumPy path is the reference: the kernel's accelerations must be its bits on random chains and on knife edges —
leaders exactly at their margin or inside it, at rest, at equal speeds, a leader's own bound softer than the one
ahead (the exact confirmation), unexpected violations, ``L(N+1)`` in any slot, slots that do not act — and the
closed loop must give the same per-scenario table with and without it (the worst-case rule with violations).
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.sim import behaviours
from safelane.sim.behaviours import leader_accels, leader_roles
from test_fast_core import needs_numba

PRM = Params()


def chains(rng: np.random.Generator, bsz: int, k: int, edges: bool):
    """``leader_accels``' arguments for ``bsz`` random chains of ``k`` slots (F, L1.., L(N+1))."""
    n_connected = rng.integers(0, k - 1, bsz)
    valid = rng.random((bsz, k)) < 0.95
    connected = rng.random((bsz, k)) < 0.9
    roles = leader_roles(valid, connected, n_connected)
    gaps = rng.uniform(-2.0, 40.0, (bsz, k))
    x = np.cumsum(gaps, axis=1)
    v = rng.uniform(0.0, 35.0, (bsz, k))
    margin = np.where(rng.random((bsz, k)) < 0.3, PRM.p_m_human, PRM.p_m)
    bounds = rng.uniform(0.0, PRM.a_x_d, (bsz, k))
    task = rng.uniform(-2.0, 2.0, (bsz, k))
    if edges:
        pick = lambda p: rng.random((bsz, k)) < p  # noqa: E731
        # gaps exactly at the margin to the vehicle ahead, vehicles at rest, equal speeds, equal bounds
        ahead = np.roll(x, -1, axis=1)
        x = np.where(pick(0.3), ahead - margin, x)
        v = np.where(pick(0.2), 0.0, v)
        v = np.where(pick(0.2), np.roll(v, -1, axis=1), v)
        bounds = np.where(pick(0.2), PRM.a_x_d, bounds)
        bounds = np.where(pick(0.2), np.roll(bounds, -1, axis=1), bounds)
        bounds = np.where(pick(0.1), 0.0, bounds)
    a_last = rng.choice([0.0, -3.0, -PRM.a_x_d, 1.0], bsz)
    decel_last = rng.uniform(3.0, PRM.a_x_d, bsz)
    violating = rng.random((bsz, k)) < 0.1
    violate_pick = rng.random((bsz, k))
    f = np.asfortranarray
    return (f(x), f(v), f(margin), roles, f(bounds), f(task), a_last, decel_last, violating, violate_pick)


def _numpy(monkeypatch, args):
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    with np.errstate(all="ignore"):
        out = leader_accels(*args, PRM)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    return out


def _bits(a, b):
    return (a == b) | (np.isnan(a) & np.isnan(b))


@needs_numba
@pytest.mark.parametrize("k", [2, 3, 5, 12])
@pytest.mark.parametrize("edges", [False, True], ids=["random", "knife edges"])
@pytest.mark.parametrize("violations", [False, True], ids=["no violations", "violations"])
def test_the_kernel_gives_the_numpy_paths_bits(monkeypatch, k, edges, violations):
    calls = []
    from safelane.sim import _fast_traffic

    real = _fast_traffic.leader_accels
    monkeypatch.setattr(_fast_traffic, "leader_accels", lambda *a: calls.append(1) or real(*a))
    args = list(chains(np.random.default_rng(100 * k + 10 * edges + violations), 3000, k, edges))
    if not violations:
        args[8] = args[9] = None
    reference = _numpy(monkeypatch, args)
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = leader_accels(*args, PRM)
    assert calls == [1] and fast.shape == reference.shape and fast.flags.f_contiguous
    same = _bits(fast, reference)
    assert same.all(), f"differs at {np.argwhere(~same)[:5]}: {fast[~same][:5]} vs {reference[~same][:5]}"
    if k > 2:  # the comparison covers the cases: leaders braking below their task, at their bound, violating
        is_last, acts = args[3]
        a = reference[acts]
        assert (a < args[5][acts]).any() and (a == -args[4][acts]).any()
        soft = acts[:, 1:-1] & (args[4][:, 1:-1] < args[4][:, 2:])
        assert soft.sum() > 100  # rows through the exact confirmation
        if violations:
            assert (args[8] & acts).any()


@needs_numba
def test_small_batches_and_the_switch_keep_the_numpy_path(monkeypatch):
    from safelane.sim import _fast_traffic

    monkeypatch.setattr(_fast_traffic, "leader_accels", lambda *a: pytest.fail("the kernel ran"))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    rows = behaviours.FAST_MIN_ELEMENTS // 4 - 1  # (rows, 4) below the threshold
    leader_accels(*chains(np.random.default_rng(1), rows, 4, True), PRM)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    leader_accels(*chains(np.random.default_rng(2), 500, 4, True), PRM)


@needs_numba
def test_the_closed_loop_gives_the_same_table_with_and_without_the_kernel(monkeypatch):
    from safelane.sim import SimConfig, concat, paper_scenarios, simulate_batch

    batch = concat([paper_scenarios(p, n, 5.0, 120, np.random.default_rng(n), p_v=0.05, first_id=1000 * n)
                    for p, n in (("CV_all", 3), ("CV_follow", 5))])  # fmt: skip
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = simulate_batch(batch, seed=4, config=SimConfig()).table
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = simulate_batch(batch, seed=4, config=SimConfig()).table
    assert fast.equals(reference)
    assert reference["n_abort"].sum() > 0 and reference["success"].any()
