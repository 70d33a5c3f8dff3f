"""The assumption monitor (``shield/monitor.py``) against time-stepped reference positions.

``tests/reference.py`` steps a braking vehicle (stopping at rest) through the period; the monitor's rule (its
docstring) is then written out here: a leader that ends the period more than ``TOL_M`` behind where braking at its
bound would have put it broke its bound (``leader_bound`` for the connected ones, ``last_decel`` for ``L(N+1)``); L1
more than ``TOL_M`` behind braking at the held plan's assumption breaks ``l1_decel`` (while the lane change is
active); a watched F (finite limit) more than ``TOL_M`` ahead of its responsible limit breaks ``follower``. The
record is cumulative and keeps the time of the first breach.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from reference import braked_position as ref_braked
from safelane import Params
from safelane.shield.monitor import BREACH_KINDS, TOL_M, Breach, Snapshot, observe_breaches, predicted_positions

PRM = Params()


def _ref_f_position(x, v, a, dt):
    """F after ``dt`` at constant acceleration ``a`` (braking ones stop at rest: time-stepped reference)."""
    braking = ref_braked(x, v, np.maximum(-a, 0.0), np.full(len(x), dt))
    return np.where(a < 0.0, braking, x + v * dt + 0.5 * a * dt * dt)


def _snapshot(rng, b, m):
    chain_x = np.cumsum(rng.uniform(8.0, 40.0, (b, m)), 1)
    chain_v = rng.uniform(0.0, 35.0, (b, m))
    chain_v[: b // 8] = rng.uniform(0.0, 0.5, (b // 8, m))  # slow ones stop inside the period
    limit = rng.uniform(-PRM.a_x_d, PRM.a_x_a, b)
    limit[rng.random(b) < 0.3] = np.inf  # not watched
    return Snapshot(
        chain_x=chain_x, chain_v=chain_v, bounds=rng.uniform(0.0, PRM.a_x_d, (b, m)),
        n_connected=rng.integers(0, m, b), f_x=rng.uniform(-60.0, -5.0, b), f_v=rng.uniform(0.0, 35.0, b),
        f_limit=limit, plan_l1_decel=rng.uniform(0.0, PRM.a_x_d, b), plan_f_aggr=rng.random(b) < 0.5,
        active=rng.random(b) < 0.7,
    )  # fmt: skip


OFFSETS = np.array([-1.0, -2.0 * TOL_M, -0.5 * TOL_M, 0.0, 0.5 * TOL_M, 2.0 * TOL_M, 0.4])


def test_breaches_match_the_time_stepped_reference():
    rng = np.random.default_rng(11)
    b, m, dt = 400, 4, PRM.dt
    last = _snapshot(rng, b, m)
    lowest = np.column_stack([ref_braked(last.chain_x[:, j], last.chain_v[:, j], last.bounds[:, j], np.full(b, dt))
                              for j in range(m)])  # fmt: skip
    l1_plan = ref_braked(last.chain_x[:, 0], last.chain_v[:, 0], last.plan_l1_decel, np.full(b, dt))
    f_high = _ref_f_position(last.f_x, last.f_v, np.where(np.isinf(last.f_limit), 0.0, last.f_limit), dt)
    # New observations near the boundaries: each leader relative to its bound's position (L1 half the time
    # relative to the plan's), F relative to its limit's.
    new_x = lowest + rng.choice(OFFSETS, (b, m))
    near_plan = rng.random(b) < 0.5
    new_x[near_plan, 0] = l1_plan[near_plan] + rng.choice(OFFSETS, near_plan.sum())
    new_f = f_high - rng.choice(OFFSETS, b)
    # A consistent previous record: some rows already breached (at t = 1.0), the others clean.
    prev_flags = np.zeros((b, len(BREACH_KINDS)), bool)
    had = rng.random(b) < 0.3
    prev_flags[had, rng.integers(0, len(BREACH_KINDS), had.sum())] = True
    prev = Breach(flags=prev_flags, first_s=np.where(had, 1.0, np.nan))
    out = observe_breaches(prev, last, SimpleNamespace(chain_x=new_x, f_x=new_f), PRM, 2.5)

    behind = new_x < lowest - TOL_M
    slots = np.arange(m)[None, :]
    expected = np.zeros((b, len(BREACH_KINDS)), bool)
    expected[:, 0] = last.active & (new_x[:, 0] < l1_plan - TOL_M)
    expected[:, 1] = (behind & (slots < last.n_connected[:, None])).any(1)
    expected[:, 2] = (behind & (slots == last.n_connected[:, None])).any(1)
    expected[:, 3] = np.isfinite(last.f_limit) & (new_f > f_high + TOL_M)
    for col in range(4):  # every kind seen and not seen
        assert 0 < expected[:, col].sum() < b
    np.testing.assert_array_equal(out.flags, prev_flags | expected)
    first = np.where(had, 1.0, np.where(expected.any(1), 2.5, np.nan))
    np.testing.assert_array_equal(out.first_s, first)
    np.testing.assert_array_equal(out.any, (prev_flags | expected).any(1))

    # predicted_positions: the chain at its bounds, a watched F at its limit.
    tx, fx = predicted_positions(last, dt)
    np.testing.assert_allclose(tx, lowest, rtol=0, atol=1e-9)
    watched = np.isfinite(last.f_limit)
    np.testing.assert_allclose(fx[watched], f_high[watched], rtol=0, atol=1e-9)


def test_a_chain_that_changed_length_skips_the_leader_comparisons():
    rng = np.random.default_rng(2)
    b = 50
    last = _snapshot(rng, b, 3)
    far_behind = last.chain_x[:, :2] - 100.0  # one vehicle fewer, everyone far behind: not compared
    f_ahead = last.f_x + 100.0  # F far ahead of any limit
    out = observe_breaches(Breach.none(b), last, SimpleNamespace(chain_x=far_behind, f_x=f_ahead), PRM, 0.3)
    assert not out.flags[:, :3].any()
    np.testing.assert_array_equal(out.flags[:, 3], np.isfinite(last.f_limit))
    np.testing.assert_array_equal(out.first_s, np.where(np.isfinite(last.f_limit), 0.3, np.nan))
    same = observe_breaches(Breach.none(b), last, SimpleNamespace(chain_x=last.chain_x - 100.0, f_x=last.f_x), PRM, 0)
    assert same.flags[:, 1:3].any(1).all() and (same.flags[:, 0] == last.active).all()


def test_only_a_finite_follower_limit_is_watched():
    """F far ahead of any position it could reach: a ``follower`` breach exactly where its limit is finite (NaN and
    ±inf are not watched, as ``np.isfinite`` says)."""
    limit = np.array([0.0, -2.0, np.nan, np.inf, -np.inf, 1.0])
    b = len(limit)
    last = Snapshot(**{**_snapshot(np.random.default_rng(4), b, 2).__dict__, "f_limit": limit})
    now = SimpleNamespace(chain_x=last.chain_x + 100.0, f_x=last.f_x + 100.0)
    out = observe_breaches(Breach.none(b), last, now, PRM, 1.0)
    np.testing.assert_array_equal(out.flags[:, 3], np.isfinite(limit))

def test_inside_the_assumptions_nothing_is_flagged_and_the_record_is_kept():
    """Everyone exactly at the assumed worst case (braking at the bound, F at its limit): no breach; a previous
    breach stays with its time."""
    rng = np.random.default_rng(3)
    b = 100
    last = _snapshot(rng, b, 4)
    last = Snapshot(**{**last.__dict__, "plan_l1_decel": last.bounds[:, 0]})
    tx, fx = predicted_positions(last, PRM.dt)
    clean = observe_breaches(Breach.none(b), last, SimpleNamespace(chain_x=tx, f_x=fx), PRM, 4.0)
    assert not clean.flags.any() and np.isnan(clean.first_s).all()
    flags = np.zeros((b, len(BREACH_KINDS)), bool)
    flags[::2, 4] = True
    prev = Breach(flags=flags, first_s=np.where(flags[:, 4], 0.7, np.nan))
    kept = observe_breaches(prev, last, SimpleNamespace(chain_x=tx, f_x=fx), PRM, 4.0)
    np.testing.assert_array_equal(kept.flags, flags)
    np.testing.assert_array_equal(kept.first_s, prev.first_s)


def test_breach_none():
    none = Breach.none(3)
    assert none.flags.shape == (3, len(BREACH_KINDS)) and none.flags.dtype == bool and not none.flags.any()
    assert none.first_s.shape == (3,) and np.isnan(none.first_s).all()
    assert none.any.tolist() == [False, False, False]
    assert BREACH_KINDS == ("l1_decel", "leader_bound", "last_decel", "follower", "stale_v2x")


def test_exactly_tol_m_beyond_the_worst_case_is_still_inside():
    """Stopped vehicles (and an F whose limit is 0 at rest) stay exactly where they are under the assumed worst case,
    so the boundary is exact in floats: ``TOL_M`` behind (ahead for F) is inside; a little more is a breach."""
    b, m = 4, 3
    x = np.array([[10.0, 30.0, 50.0]] * b)
    last = Snapshot(
        chain_x=x, chain_v=np.zeros((b, m)), bounds=np.full((b, m), 3.0), n_connected=np.array([0, 1, 2, 2]),
        f_x=np.full(b, -20.0), f_v=np.zeros(b), f_limit=np.zeros(b), plan_l1_decel=np.full(b, 3.0),
        plan_f_aggr=np.zeros(b, bool), active=np.ones(b, bool),
    )  # fmt: skip
    at = observe_breaches(Breach.none(b), last, SimpleNamespace(chain_x=x - TOL_M, f_x=last.f_x + TOL_M), PRM, 1.0)
    assert not at.flags.any()
    beyond = observe_breaches(
        Breach.none(b), last, SimpleNamespace(chain_x=x - 2 * TOL_M, f_x=last.f_x + 2 * TOL_M), PRM, 1.0
    )
    assert beyond.flags[:, [0, 3]].all() and beyond.flags[:, 1].tolist() == [False, True, True, True]
    assert beyond.flags[:, 2].all()
