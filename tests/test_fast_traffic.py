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
from test_fast_core import needs_numba, period_by_period  # noqa: F401 (a fixture)

pytestmark = [pytest.mark.compiled, pytest.mark.usefixtures("period_by_period")]


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
        _, acts = args[3]
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


def followers(rng: np.random.Generator, n: int):
    """``follower_accel``'s positional arguments for ``n`` random followers: near and far from L1 and the ego, at
    rest, at equal speeds, the ego behind F, inside the gap-opening distance or past it."""
    f_x = rng.uniform(-60.0, 0.0, n)
    gap0 = rng.uniform(5.0, 25.0, n)
    ego_x = f_x + np.where(rng.random(n) < 0.2, rng.uniform(-5.0, 0.0, n), gap0 + rng.uniform(-3.0, 6.0, n))
    l1_x = f_x + np.where(rng.random(n) < 0.3, PRM.p_m + rng.uniform(-0.5, 1.0, n), rng.uniform(10.0, 80.0, n))
    f_v = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.0, 35.0, n))
    l1_v = np.where(rng.random(n) < 0.3, f_v, rng.uniform(0.0, 35.0, n))
    ego_vx = np.where(rng.random(n) < 0.3, f_v, rng.uniform(0.0, 35.0, n))
    aggressive, completed = rng.random(n) < 0.5, rng.random(n) < 0.5
    return f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, completed, gap0


@needs_numba
@pytest.mark.parametrize("hook", [False, True], ids=["nominal laws", "a hook's wish"])
@pytest.mark.parametrize("ignores_ego", [False, True])
def test_the_follower_kernel_gives_the_numpy_paths_bits(monkeypatch, hook, ignores_ego):
    from safelane.sim import _fast_traffic

    calls = []
    real = _fast_traffic.follower_accel
    monkeypatch.setattr(_fast_traffic, "follower_accel", lambda *a: calls.append(1) or real(*a))
    rng = np.random.default_rng(7 + 2 * hook + ignores_ego)
    args = followers(rng, 4000)
    kw = dict(wanted=rng.uniform(-PRM.a_x_d, PRM.a_x_a, 4000) if hook else None, ignores_ego=ignores_ego)
    call = lambda: behaviours.follower_accel(*args, PRM, 1.0, 2.0, **kw)  # noqa: E731
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    with np.errstate(all="ignore"):
        reference = call()
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    fast = call()
    assert calls == [1]
    same = _bits(fast, reference)
    assert same.all(), f"differs at {np.flatnonzero(~same)[:5]}: {fast[~same][:5]} vs {reference[~same][:5]}"
    # the cases occur: braking for L1 or the ego (below the wish), at -a_x_d, and the wish kept
    assert (reference == -PRM.a_x_d).any() and (reference > -PRM.a_x_d).sum() > 1000


@needs_numba
@pytest.mark.parametrize("n_leaders", [0, 1, 3, 10])
def test_the_chain_kernel_gives_the_numpy_scans_bits(monkeypatch, n_leaders):
    """``ClosedLoop.chain`` with and without the kernel, on chains with gaps at, inside and beyond the margins, at
    rest and at equal speeds, some links human-driven and some leaders not connected."""
    from safelane.planners.base import ExpertPlanner
    from safelane.sim import SimConfig, paper_scenarios
    from safelane.sim.step import ClosedLoop

    rng = np.random.default_rng(n_leaders)
    batch = paper_scenarios("CV_all", n_leaders, 5.0, 3000, rng)
    k = batch.x.shape[1]
    batch.human[:] = rng.random(batch.human.shape) < 0.3
    batch.n_connected[:] = rng.integers(0, n_leaders + 1, len(batch))
    loop = ClosedLoop(batch, 0, PRM, SimConfig(), ExpertPlanner())
    x = np.asfortranarray(batch.x + rng.uniform(-6.0, 6.0, batch.x.shape) * (rng.random(batch.x.shape) < 0.5))
    v = np.asfortranarray(np.where(rng.random(x.shape) < 0.2, 0.0, rng.uniform(0.0, 35.0, x.shape)))
    v[:, 1:] = np.where(rng.random((len(v), k - 1)) < 0.2, v[:, :-1], v[:, 1:])  # equal speeds
    state = type("S", (), {"x": x, "v": v})()
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    ref_bounds, ref_unsafe = loop.chain(state)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    bounds, unsafe = loop.chain(state)
    assert bounds.shape == ref_bounds.shape == (len(x), k)
    assert _bits(bounds, ref_bounds).all() and np.array_equal(unsafe, ref_unsafe)
    if n_leaders:  # unsafe links and bounds between the promise and a_x_d occur
        assert ref_unsafe.any() and not ref_unsafe.all()
        inner = ref_bounds[:, 1:-1]
        assert ((inner > 0.5) & (inner < PRM.a_x_d)).any()
