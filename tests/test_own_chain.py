"""The own lane as a connected chain (sim/own_chain.py, docs/real_roads.md "A connected own lane"): the drawn chain
has its documented ranges and leaves L0's own draws alone; every connected own-lane vehicle brakes no harder than
its chain bound from the independent reference (``tests/reference.py``'s bisection), and harder than its promise
only where the vehicle ahead forces it; the shield reads the chain and keeps ``p_m`` inside the assumptions; bad
chain fields are named; the falsifier searches connected own lanes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from reference import ref_leader_chain
from safelane import Params
from safelane.experiments import falsify_space as space
from safelane.experiments.falsify import OUTCOMES, Setting, evaluate
from safelane.planners.base import ExpertPlanner
from safelane.shield.realworld import own_lane_decel
from safelane.sim import SimConfig, simulate
from safelane.sim.own_chain import check_chain
from safelane.sim.preset import load_preset
from safelane.sim.realworld import with_own_lane
from safelane.sim.scenario import paper_scenarios
from safelane.sim.step import ClosedLoop

REALISTIC = load_preset("realistic")
PRM = REALISTIC.params


def _config(n: int, **kw) -> SimConfig:
    return REALISTIC.sim.model_copy(update={"own_lane_connected": n, **kw})


def _batch(rows: int, seed: int = 0, n_leaders: int = 3, decel: float = 6.0):
    return paper_scenarios("CV_all", n_leaders, decel, rows, np.random.default_rng(seed))


def test_drawn_chain_has_its_documented_ranges_and_keeps_l0():
    cfg = _config(3, l0_gap_min_m=20.0, l0_gap_max_m=50.0, l0_speed_spread_mps=2.0, own_promise_decel=1.5,
                  l0_brake_window_s=3.0)  # fmt: skip
    base = _batch(400)
    alone = with_own_lane(base, 7, cfg.model_copy(update={"own_lane_connected": 0}), PRM)
    chain = with_own_lane(base, 7, cfg, PRM)
    for name in ("l0_x", "l0_v", "l0_profile_t", "l0_profile_a"):  # L0's draws are what they were without the chain
        assert np.array_equal(getattr(alone, name), getattr(chain, name)), name
    assert alone.own_ahead_x is None
    x = np.column_stack([chain.l0_x, chain.own_ahead_x])
    v = np.column_stack([chain.l0_v, chain.own_ahead_v])
    gaps, dv = np.diff(x, axis=1), np.diff(v, axis=1)
    assert ((gaps >= 20.0) & (gaps <= 50.0)).all() and gaps.std() > 5.0
    assert ((dv >= 0.0) & (dv <= 2.0)).all() and dv.std() > 0.3
    assert (chain.own_promise == 1.5).all() and (chain.own_n_connected == 3).all()
    assert ((chain.own_brake_t >= 0.0) & (chain.own_brake_t <= 3.0)).all() and chain.own_brake_t.std() > 0.5
    again = with_own_lane(base, 7, cfg, PRM)
    assert np.array_equal(again.own_ahead_x, chain.own_ahead_x)  # counter-based: the same seed, the same chain
    other = with_own_lane(base, 8, cfg, PRM)
    assert not np.array_equal(other.own_ahead_x, chain.own_ahead_x)
    with pytest.raises(ValueError, match=r"own_promise_decel=7\.0 must be <= a_x_d=6\.0"):
        with_own_lane(base, 7, cfg.model_copy(update={"own_promise_decel": 7.0}), PRM)


def _run(loop: ClosedLoop, steps: int):
    """States of the own lane at every period boundary, and the loop's last state."""
    s = loop.initial_state()
    xs, vs = [s.l0[0].copy()], [s.l0[1].copy()]
    for _ in range(steps):
        s = loop.step(s)[0]
        xs.append(s.l0[0].copy())
        vs.append(s.l0[1].copy())
    return np.stack(xs), np.stack(vs), s


def test_connected_own_lane_vehicles_brake_no_harder_than_the_reference_chain_bound():
    """Each period, a connected vehicle's braking (its speed change over a period it does not stop in) is at most
    the smallest worst case the reference chain analysis has given it so far (on the states at each period's
    start): its promise, or what the vehicle ahead's worst case forces — and never more later, which is what a held
    plan relies on. The head brakes at a_o_d = 9.5, so the expected violations happen."""
    n, rows, steps = 3, 40, 80
    cfg = _config(n, l0_gap_min_m=12.0, l0_gap_max_m=30.0, l0_brake_window_s=1.0, horizon_s=steps * PRM.dt)
    loop = ClosedLoop(with_own_lane(_batch(rows, seed=3), 11, cfg, PRM), 11, PRM, cfg, ExpertPlanner())
    xs, vs, last = _run(loop, steps)
    promise = loop.b.own_promise
    bound = np.full((rows, n), np.inf)
    beyond = checked = 0
    for p in range(steps):
        bound = np.minimum(bound, ref_leader_chain(xs[p], vs[p], promise, PRM).decel[:, :n])
        moving = vs[p + 1, :, :n] > 0.0
        decel = (vs[p, :, :n] - vs[p + 1, :, :n]) / PRM.dt
        ok = ~moving | (decel <= bound + 1e-6)
        assert ok.all(), (p, np.argwhere(~ok)[:3], decel[~ok][:3], bound[~ok][:3])
        beyond += int((moving & (decel > promise + 0.5)).sum())
        checked += int(moving.sum())
    assert checked > 2000 and beyond > 20  # the bound was reached beyond the promise, not only the promise kept
    assert not last.own_pair_collided.any()
    assert (np.diff(xs, axis=2) >= PRM.vehicle_length).all()  # consecutive own-lane vehicles never overlap


def test_connected_vehicles_keep_their_task_where_it_is_safe():
    """1.5 km apart (where even the head's worst case, 9.5 m/s², asks less of them than their promise), each
    connected vehicle holds its speed until its own instant, then brakes at exactly its promise (the adversarial
    timing inside the assumptions)."""
    cfg = _config(2, l0_gap_min_m=1500.0, l0_gap_max_m=1500.0, l0_speed_spread_mps=2.0, l0_brake_window_s=2.0,
                  l0_decel_mps2=1e-9)  # fmt: skip
    loop = ClosedLoop(with_own_lane(_batch(16, seed=4), 5, cfg, PRM), 5, PRM, cfg, ExpertPlanner())
    _, vs, _ = _run(loop, 30)
    t = np.arange(30) * PRM.dt
    acc = np.diff(vs, axis=0) / PRM.dt  # (steps, B, K)
    brake_t = loop.b.own_brake_t
    for j in range(2):
        late = t[:, None] >= brake_t[None, :, j] + 1e-9
        assert np.allclose(acc[:, :, j][late], -0.5, atol=1e-9)
        assert np.allclose(acc[:, :, j][~late], 0.0, atol=1e-9)
        assert late.any() and (~late).any()


def test_the_shield_reads_the_chain_and_its_bound_is_the_reference():
    cfg = _config(2)
    loop = ClosedLoop(with_own_lane(_batch(64, seed=5), 2, cfg, PRM), 2, PRM, cfg, ExpertPlanner())
    s = loop.initial_state()
    sit = loop.situation(0.0, s.ego, s.x, s.v, None, s.v[:, 0], s.l0)
    assert sit.own_x.shape == (64, 3) and (sit.own_n_connected == 2).all() and (sit.own_promise == 0.5).all()
    mine = own_lane_decel(sit, PRM, np.ones(64, bool), np.zeros(64, bool))
    ref = ref_leader_chain(sit.own_x, sit.own_v, sit.own_promise, PRM)
    expect = np.where(ref.unsafe, PRM.others_decel, ref.decel[:, 0])
    assert np.allclose(mine, expect, atol=1e-6)
    assert (mine < PRM.others_decel - 1.0).sum() > 10  # the connection softens L0's worst case in most rows


@pytest.mark.parametrize(("planner", "n"), [("CV_all", 1), ("CV_none", 3), ("No_agg_assess", 2)])
def test_the_shield_keeps_p_m_with_a_connected_own_lane(planner, n):
    """The realistic preset (L(N+1) and the head brake up to a_o_d = 9.5, sensing errors, 0.2 s delay) with a
    connected own lane: no collision and no p_m violation in the rows that start inside the assumptions, and the
    own lane's vehicles never run into each other."""
    res = simulate(planner, n_leaders=3, decel=9.0, samples=150, seed=n, preset="realistic", config=_config(n))
    table = res.table
    inside = table[table.initial_safe]
    assert len(inside) > 40
    assert not inside.collision.any() and not inside.safety_violation.any()
    assert not table.own_lane_leader_collision.any()


def _chain_batch():
    return with_own_lane(_batch(4), 1, _config(2), PRM)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"own_promise": np.full((4, 2), 7.0)}, r"own_promise must lie in \[0, a_x_d=6.0\]; got 7.0"),
        ({"own_n_connected": np.full(4, 3)}, r"own_n_connected must be \(4,\) in \[0, J=2\]"),
        ({"own_brake_t": np.full((4, 2), -1.0)}, "own_brake_t must be >= 0"),
        ({"own_ahead_v": np.zeros((4, 3))}, r"own_ahead_v must have shape \(4, 2\)"),
        ({"own_brake_t": None}, "go together"),
        ({"own_n_connected": np.full(4, 1)}, "exactly the own_n_connected vehicles ahead of L0"),
    ],
)
def test_bad_chain_fields_are_named(change, message):
    with pytest.raises(ValueError, match=message):
        check_chain(dataclasses.replace(_chain_batch(), **change), PRM)


def test_disordered_chain_is_named():
    b = _chain_batch()
    x = b.own_ahead_x.copy()
    x[0, 1] = x[0, 0] - 1.0
    with pytest.raises(ValueError, match="must be ordered"):
        check_chain(dataclasses.replace(b, own_ahead_x=x), PRM)


def test_the_falsifier_searches_connected_own_lanes():
    """The realistic world's specs put chains of 1..3 connected vehicles ahead of the ego in a quarter of the rows
    or more; the rows inside the assumptions simulate with no collision and no p_m violation."""
    rng = np.random.default_rng(9)
    prm = Params()
    u = rng.uniform(size=(600, space.dimension(prm, "realistic")))
    spec = space.decode(u, prm, 0.0, "realistic")
    assert set(np.unique(spec["own_n"])) == {0, 1, 2, 3} and (spec["own_n"] > 0).mean() > 0.25
    setting = Setting.realistic(params=prm)
    outcome = evaluate(spec, setting)[0]
    chained = outcome[np.asarray(spec["own_n"])[outcome["row"].to_numpy()] > 0]
    assert len(chained) > 50
    assert not chained[list(OUTCOMES)].to_numpy(bool).any()


def test_each_bad_chain_field_alone_is_named():
    """Each condition of the check on its own (one field wrong, the rest valid), and the bad value named even where
    other entries sit exactly on the range's ends."""
    b = _chain_batch()
    n, j = b.own_ahead_x.shape
    cases = [
        ({"own_ahead_x": b.own_ahead_x[:-1]}, r"own_ahead_x must have shape \(4, J >= 1\)"),  # wrong rows, J >= 1
        ({"own_ahead_x": b.own_ahead_x[:, :, None]}, r"own_ahead_x must have shape"),  # 3-D, right rows
        ({"own_brake_t": np.zeros((n, j + 1))}, r"own_brake_t must have shape \(4, 2\)"),
        ({"own_n_connected": np.array([2, 2, -1, 2])}, r"own_n_connected must be \(4,\) in \[0, J=2\]"),
        ({"own_ahead_v": np.where(np.arange(j) == 1, -0.5, b.own_ahead_v)}, "own_ahead_v finite and >= 0"),
        ({"own_ahead_x": np.where(np.arange(j) == 1, -np.inf, b.own_ahead_x)}, "must be finite or \\+inf"),
    ]
    for change, message in cases:
        with pytest.raises(ValueError, match=message):
            check_chain(dataclasses.replace(b, **change), PRM)
    edges = np.array([[0.0, PRM.a_x_d], [PRM.a_x_d, 0.0], [0.0, 6.5], [0.0, 0.0]])  # one bad value, 6.5
    with pytest.raises(ValueError, match=r"own_promise must lie in \[0, a_x_d=6.0\]; got 6.5"):
        check_chain(dataclasses.replace(b, own_promise=edges), PRM)


def test_the_ranges_ends_are_accepted():
    """Promises of exactly 0 and exactly a_x_d, braking from t = 0, a vehicle exactly at the one behind it."""
    b = _chain_batch()
    x = b.own_ahead_x.copy()
    x[:, 0] = b.l0_x  # at L0's position: ordered (not behind it)
    x[:, 1] = x[:, 0]
    check_chain(dataclasses.replace(b, own_promise=np.array([[0.0, PRM.a_x_d]] * 4), own_brake_t=np.zeros((4, 2)),
                                    own_ahead_x=x), PRM)  # fmt: skip


def test_braking_from_t_0_starts_in_the_first_period():
    """A connected vehicle whose instant is t = 0 brakes at its promise in the very first period (the comparison
    is ``t >= brake_t`` up to TIME_TOL_S, never ``t > brake_t``); a kilometre apart nothing caps it."""
    cfg = _config(2, l0_gap_min_m=1500.0, l0_gap_max_m=1500.0, l0_decel_mps2=1e-9)
    b = with_own_lane(_batch(8, seed=4), 5, cfg, PRM)
    b = dataclasses.replace(b, own_brake_t=np.zeros_like(b.own_brake_t))
    loop = ClosedLoop(b, 5, PRM, cfg, ExpertPlanner())
    _, vs, _ = _run(loop, 2)
    acc = (vs[1] - vs[0]) / PRM.dt
    np.testing.assert_allclose(acc[:, :2], -0.5, atol=1e-9)  # L0 and the vehicle ahead of it: the connected two


def test_the_chains_draws_are_independent_of_each_other_and_of_l0s():
    """Every drawn quantity — each vehicle's gap to the one behind, its speed over that one's, its braking instant,
    L0's included — on its own counter: over 4,000 scenarios no two are correlated (|r| < 0.08; equal counters would
    give r = 1). And a promise of exactly a_x_d is allowed (the end of its range)."""
    cfg = _config(3, own_promise_decel=PRM.a_x_d)
    b = with_own_lane(paper_scenarios("CV_all", 1, 5.0, 4000, np.random.default_rng(9)), 11, cfg, PRM)
    x = np.column_stack([b.ego_x, b.l0_x, b.own_ahead_x])
    v = np.column_stack([b.ego_vx, b.l0_v, b.own_ahead_v])
    brake = np.column_stack([b.l0_profile_t[:, 1], b.own_brake_t])
    drawn = np.column_stack([np.diff(x, axis=1), np.diff(v, axis=1), brake])  # (4000, 12)
    r = np.corrcoef(drawn.T)
    assert np.abs(r[~np.eye(len(r), dtype=bool)]).max() < 0.08
    assert (b.own_promise == PRM.a_x_d).all()


def test_only_the_connected_vehicles_links_count_where_the_chain_is_shorter_than_its_slots():
    """A batch with three slots ahead of L0 but one vehicle there (own_n_connected = 1: L0 connected, the head
    ahead of it, two empty slots): L0's running bound after a period is the reference chain's over (L0, head) with
    the head at a_o_d — the head's link to the empty slot beyond it is no connected link."""
    b = with_own_lane(_batch(32, seed=6), 4, _config(3, l0_gap_min_m=10.0, l0_gap_max_m=25.0), PRM)
    x = b.own_ahead_x.copy()
    x[:, 1:] = np.inf
    b = dataclasses.replace(b, own_ahead_x=x, own_n_connected=np.ones(32, np.int64))
    check_chain(b, PRM)
    cfg = _config(3, l0_gap_min_m=10.0, l0_gap_max_m=25.0)
    loop = ClosedLoop(b, 4, PRM, cfg, ExpertPlanner())
    s0 = loop.initial_state()
    s1 = loop.step(s0)[0]
    p = np.column_stack([s0.l0[0][:, 0], s0.l0[0][:, 1]])
    v = np.column_stack([s0.l0[1][:, 0], s0.l0[1][:, 1]])
    ref = ref_leader_chain(p, v, b.own_promise[:, :1], PRM).decel[:, 0]
    np.testing.assert_allclose(s1.own_cap[:, 0], ref, rtol=0, atol=1e-6)
    assert (ref > b.own_promise[:, 0] + 0.1).any()  # the head's worst case forces more than L0's promise somewhere
