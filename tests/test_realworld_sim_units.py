"""``sim/realworld.py`` unit by unit against independent references: the ego's checks against an own-lane leader
``L0`` (dense-time reference of ``test_sim_checks_reference``: the window is ``y < w_v``), the execution of an issued
command (segment-by-segment integration), the drawn L0 (its documented ranges), and L0's profile over a period."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.shield.command import Command
from safelane.sim import SimConfig
from safelane.sim.kinematics import Fleet, Motion
from safelane.sim.own_chain import OwnLane
from safelane.sim.realworld import executed_motion, own_lane_checks, with_own_lane
from safelane.sim.scenario import paper_scenarios
from test_sim_checks_reference import GRID, _plan_segments, crossings, scenarios, trajectory

#: The checks and motions divide only where it is safe (or under errstate): no floating-point warning escapes.
pytestmark = pytest.mark.filterwarnings("error")

PARAMS = Params()
DT = PARAMS.dt
LEVEL = PARAMS.vehicle_width


@pytest.mark.parametrize(("seed", "planned"), [(21, False), (22, True)])
def test_own_lane_checks_match_the_dense_reference(seed, planned):
    """Collision: ``|x0 − x| < length`` while ``y < w_v``; violation: ``|x0 − x| < p_m`` at those instants, until the
    lane change completes; the reported minimum gap is the exact minimum of ``x0 − x`` over those instants."""
    _, _, lon, lat, _, plan, world = scenarios(seed, bsz=300, planned=planned)
    rng = np.random.default_rng(seed)
    n = len(world["ex"])
    world["ey"][:] = LEVEL + rng.uniform(-0.3, 0.3, n)  # around the own lane's edge
    lat = Motion.free(world["ey"], world["evy"], lat.acc[:, 0], DT)
    if plan is not None:  # the planned rows' lateral motion moved by the same offset
        rows, plan_lon, plan_lat = plan
        shift = world["ey"][rows] - plan_lat.x[:, 0]
        plan = (rows, plan_lon, Motion(t=plan_lat.t, x=plan_lat.x + shift[:, None], v=plan_lat.v, acc=plan_lat.acc))
    x0 = world["ex"] + rng.uniform(-3.0, 12.0, n)
    v0 = np.maximum(world["evx"] + rng.normal(0.0, 3.0, n), 0.0)
    a1, a2 = rng.uniform(-8.0, 2.5, n), rng.uniform(-8.0, 2.5, n)
    t_sw = np.where(rng.uniform(size=n) < 0.4, rng.uniform(0.0, DT, n), DT)
    l0 = Fleet.switched(x0, v0, a1, t_sw, a2, DT).motion(...)
    present = rng.uniform(size=n) < 0.9
    completed = rng.uniform(size=n) < 0.3
    collided, violated, min_gap = own_lane_checks(PARAMS, lon, lat, plan, l0, present, completed)
    counts = dict(collided=0, violated=0, completed_close=0, skipped=0, empty=0)
    for i in range(n):
        if not present[i]:
            assert not collided[i] and not violated[i] and min_gap[i] == np.inf
            continue
        (sx, ax), (sy, ay) = world["ego"][i]
        cross = crossings(world["ey"][i], world["evy"][i], sy, ay, LEVEL)
        t = np.unique(np.concatenate([GRID, cross]))
        ex = trajectory(world["ex"][i], world["evx"][i], sx, ax, t)[0]
        ey = trajectory(world["ey"][i], world["evy"][i], sy, ay, t, clamp=False)[0]
        segs = ([0.0, t_sw[i]], [a1[i], a2[i]]) if t_sw[i] < DT else ([0.0], [a1[i]])
        gap = trajectory(x0[i], v0[i], *segs, t)[0] - ex
        win = (ey < LEVEL) | np.isin(t, cross)
        lo, hi = gap[win].min(initial=np.inf), gap[win].max(initial=-np.inf)
        counts["empty"] += lo == np.inf
        assert min_gap[i] == pytest.approx(lo, abs=1e-7), i
        edges = (lo - PARAMS.vehicle_length, hi + PARAMS.vehicle_length, lo - PARAMS.p_m, hi + PARAMS.p_m)
        if min(abs(e) for e in edges) < 1e-7:
            counts["skipped"] += 1
            continue
        col = lo < PARAMS.vehicle_length and hi > -PARAMS.vehicle_length
        close = lo < PARAMS.p_m and hi > -PARAMS.p_m
        assert (bool(collided[i]), bool(violated[i])) == (col, close and not completed[i]), i
        counts["collided"] += col
        counts["violated"] += close and not completed[i]
        counts["completed_close"] += close and completed[i] and not col
    assert counts["collided"] >= 5 and counts["violated"] >= 5 and counts["completed_close"] >= 3
    assert counts["empty"] >= 5 and counts["skipped"] <= 3, counts


def test_executing_an_issued_plan_from_its_own_start_reproduces_it():
    """``issued`` turns a decision's abort knots into per-segment accelerations; ``executed_motion`` integrates them
    from the ego's state (stopping at rest): from the plan's own start state it reproduces the plan's knots, and its
    motion matches segment-by-segment integration between them. The other rows drive their constant command."""
    rng = np.random.default_rng(3)
    n, rows = 12, np.array([1, 4, 5, 9])
    ex, evx = rng.uniform(-5, 5, n), rng.uniform(0.0, 30.0, n)
    evx[4] = 0.2  # stops inside the plan (at a knot: the plans' stops are knots)
    ey, evy = rng.uniform(0, 3.5, n), rng.uniform(-1, 1, n)
    parts = [_plan_segments(rng, ex[r], evx[r], ey[r], evy[r]) for r in rows]
    knots = np.stack([p[0] for p in parts])
    knots[0, 2] = knots[0, 1]  # a repeated knot: a zero-length segment
    parts[0] = _plan_segments(np.random.default_rng(0), ex[1], evx[1], ey[1], evy[1], knots[0])
    ax, ay = np.array([p[1] for p in parts]), np.array([p[2] for p in parts])
    px, vx, py, vy = (np.stack([p[i] for p in parts]) for i in (3, 4, 5, 6))
    a_x, a_y = rng.uniform(-8.0, 2.5, n), rng.uniform(-1.5, 1.5, n)
    decision = SimpleNamespace(
        a_x=a_x, a_y=a_y, completing=np.arange(n) % 3 == 0, abort_motion=lambda: (rows, knots, px, vx, py, vy)
    )
    cmd = Command.of(decision)
    np.testing.assert_array_equal(cmd.rows, rows)
    np.testing.assert_array_equal(cmd.completing, decision.completing)
    assert (cmd.ax_seg[0, 1] == 0.0) and (cmd.ay_seg[0, 1] == 0.0)  # the zero-length segment
    lon, lat, plan = executed_motion(cmd, (ex, ey, evx, evy), DT)
    ref_lon, ref_lat = Motion.constant(ex, evx, a_x, DT), Motion.free(ey, evy, a_y, DT)
    for f in ("t", "x", "v", "acc"):
        np.testing.assert_array_equal(getattr(lon, f), getattr(ref_lon, f))
        np.testing.assert_array_equal(getattr(lat, f), getattr(ref_lat, f))
    got_rows, plan_lon, plan_lat = plan
    # the hosts (highway-env, SUMO) take the end of the period from Command.carry: the same state, bit for bit
    end = cmd.carry(ex, ey, evx, evy, DT)
    want = [lon.end[0].copy(), lat.end[0].copy(), lon.end[1].copy(), lat.end[1].copy()]
    for k, q in enumerate((plan[1].end[0], plan[2].end[0], plan[1].end[1], plan[2].end[1])):
        want[k][rows] = q
    for got_q, want_q in zip(end, want, strict=True):
        np.testing.assert_array_equal(got_q, want_q)
    np.testing.assert_array_equal(got_rows, rows)
    np.testing.assert_allclose(plan_lon.x, px, rtol=0, atol=1e-9)
    np.testing.assert_allclose(plan_lon.v, vx, rtol=0, atol=1e-9)
    np.testing.assert_allclose(plan_lat.x, py, rtol=0, atol=1e-9)
    np.testing.assert_allclose(plan_lat.v, vy, rtol=0, atol=1e-9)
    xq = plan_lon.at(np.broadcast_to(GRID, (4, GRID.size)))[0]
    yq = plan_lat.at(np.broadcast_to(GRID, (4, GRID.size)))[0]
    for k, r in enumerate(rows):
        np.testing.assert_allclose(xq[k], trajectory(ex[r], evx[r], list(knots[k, :-1]), list(ax[k]), GRID)[0],
                                   rtol=0, atol=1e-9)  # fmt: skip
        ref_y = trajectory(ey[r], evy[r], list(knots[k, :-1]), list(ay[k]), GRID, clamp=False)[0]
        np.testing.assert_allclose(yq[k], ref_y, rtol=0, atol=1e-9)
    assert (vx[1:2, 1:] == 0.0).any()  # the plan that stops


def test_cruise_and_a_decision_without_aborts():
    c = Command.idle(3)
    np.testing.assert_array_equal(c.a_x, 0.0)
    np.testing.assert_array_equal(c.a_y, 0.0)
    assert c.rows.size == 0 and c.rows.dtype == np.intp and not c.completing.any() and c.completing.shape == (3,)
    assert c.knots is None and c.ax_seg is None and c.ay_seg is None
    lon, lat, plan = executed_motion(c, (np.zeros(3), np.ones(3), np.full(3, 20.0), np.zeros(3)), DT)
    assert plan is None
    np.testing.assert_allclose(lon.x[:, -1], 2.0)
    np.testing.assert_allclose(lat.x[:, -1], 1.0)
    empty = np.zeros(0, np.intp)
    decision = SimpleNamespace(a_x=np.ones(2), a_y=np.zeros(2), completing=np.ones(2, bool),
                               abort_motion=lambda: (empty, np.zeros((0, 5)), *(np.zeros((0, 5)),) * 4))  # fmt: skip
    cmd = Command.of(decision)
    assert cmd.ax_seg is None and cmd.ay_seg is None and cmd.completing.all()


def _batch(samples=400):
    return paper_scenarios("CV_all", 3, 4.0, samples, np.random.default_rng(0))


def test_drawn_l0_lies_in_its_documented_ranges():
    batch, cfg = _batch(), SimConfig()
    out = with_own_lane(batch, 7, cfg, PARAMS)
    gap = out.l0_x - batch.ego_x
    assert (gap >= cfg.l0_gap_min_m).all() and (gap <= cfg.l0_gap_max_m).all()
    assert gap.min() < cfg.l0_gap_min_m + 2.0 and gap.max() > cfg.l0_gap_max_m - 2.0  # spread over the range
    spread = out.l0_v - batch.ego_vx
    assert (spread >= 0.0).all() and (spread <= cfg.l0_speed_spread_mps).all() and spread.max() > 2.5
    np.testing.assert_array_equal(out.l0_profile_t[:, 0], 0.0)
    assert (out.l0_profile_t[:, 1] >= 0.0).all() and (out.l0_profile_t[:, 1] <= cfg.l0_brake_window_s).all()
    assert out.l0_profile_t[:, 1].max() > cfg.l0_brake_window_s - 0.1
    np.testing.assert_array_equal(out.l0_profile_a, np.stack([np.zeros(len(gap)), np.full(len(gap), -PARAMS.a_x_d)], 1))
    # Deterministic per (seed, scenario); another seed draws otherwise; a given L0 is kept.
    again = with_own_lane(batch, 7, cfg, PARAMS)
    np.testing.assert_array_equal(again.l0_x, out.l0_x)
    assert not np.array_equal(with_own_lane(batch, 8, cfg, PARAMS).l0_x, out.l0_x)
    assert with_own_lane(out, 9, cfg, PARAMS) is out
    soft = with_own_lane(batch, 7, SimConfig(l0_decel_mps2=3.0), PARAMS)
    np.testing.assert_array_equal(soft.l0_profile_a[:, 1], -3.0)
    # The falsifier's world key replaces the scenario id as the draws' key.
    keyed = dataclasses.replace(batch, world_key=batch.scenario_id[::-1].copy())
    np.testing.assert_array_equal(with_own_lane(keyed, 7, cfg, PARAMS).l0_x - batch.ego_x, gap[::-1])


def test_l0_motion_follows_its_profile_over_a_period():
    """L0 cruises, then brakes from its profile's instant: the period's motion against segment-by-segment
    integration, for periods before, across and after the switch."""
    batch = with_own_lane(_batch(50), 3, SimConfig(l0_brake_window_s=0.3), PARAMS)
    lane = OwnLane.of(batch, PARAMS)
    x, v = batch.l0_x, batch.l0_v
    t_brake = batch.l0_profile_t[:, 1]
    for t in (0.0, 0.1, 0.2, 0.3):
        fleet, _ = lane.period(batch, t, x[:, None], v[:, None], None, PARAMS)
        motion, (x1, v1) = fleet.motion(slice(None), 0), (fleet.x_end[:, 0], fleet.v_end[:, 0])
        xq, vq = motion.at(np.broadcast_to(GRID, (len(x), GRID.size)))
        for i in range(len(x)):
            rel = t_brake[i] - t
            segs = (
                ([0.0], [-PARAMS.a_x_d])
                if rel <= 1e-9
                else ([0.0, rel], [0.0, -PARAMS.a_x_d])
                if rel < DT
                else ([0.0], [0.0])
            )
            ref_x, ref_v = trajectory(x[i], v[i], *segs, GRID)
            np.testing.assert_allclose(xq[i], ref_x, rtol=0, atol=1e-9)
            np.testing.assert_allclose(vq[i], ref_v, rtol=0, atol=1e-9)
            assert x1[i] == pytest.approx(ref_x[-1], abs=1e-9) and v1[i] == pytest.approx(ref_v[-1], abs=1e-9)
        x, v = x1, v1


def _situation(b=300, m=5, k=3):
    from test_realworld import measured

    s = measured(np.random.default_rng(11), PARAMS, b, m, k)
    return dataclasses.replace(s, err_f=None, err_chain=None, err_own=None)


def _normalized(meas, true, bound):
    """The drawn error as a share of its bound, in [-1, 1] (nan where the bound is 0)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return (meas - true) / bound


def test_measurement_errors_lie_inside_their_bounds_and_are_independent():
    """Each position and speed is off by a uniform share of its bound (speeds kept >= 0), drawn afresh for every
    vehicle, coordinate, step and scenario key: no two coordinates share a draw; the bounds are those of
    ``SensingBounds.apply`` (by connectivity)."""
    from safelane.shield import SensingBounds
    from safelane.sim.realworld import measure

    s = _situation()
    bounds = SensingBounds()
    batch = SimpleNamespace(scenario_id=np.arange(len(s.f_x)) + 100, world_key=None)
    out = measure(5, batch, 3, s, bounds)
    want = bounds.apply(s)
    for f in ("err_f", "err_chain", "err_own"):
        np.testing.assert_array_equal(getattr(out, f), getattr(want, f))
    present = np.isfinite(s.own_x)
    shares = {
        "f_x": _normalized(out.f_x, s.f_x, want.err_f[:, 0]),
        "chain_x": _normalized(out.chain_x, s.chain_x, want.err_chain[..., 0]),
        "own_x": _normalized(out.own_x[present], s.own_x[present], want.err_own[..., 0][present]),
    }
    for name, (meas, true, err) in {
        "f_v": (out.f_v, s.f_v, want.err_f[:, 1]),
        "chain_v": (out.chain_v, s.chain_v, want.err_chain[..., 1]),
        "own_v": (out.own_v[present], s.own_v[present], want.err_own[..., 1][present]),
    }.items():
        assert (meas >= 0.0).all()
        unclipped = meas > 0.0
        shares[name] = np.where(unclipped, _normalized(meas, true, err), np.nan)
        assert (true[~unclipped] <= err[~unclipped] + 1e-12).all()  # clipped only where the bound reaches 0
    for name, share in shares.items():
        share = share[np.isfinite(share)]
        assert share.size > 100, name
        assert (np.abs(share) <= 1.0 + 1e-9).all(), name
        assert share.min() < -0.9 and share.max() > 0.9 and abs(share.mean()) < 0.15, name
    # Absent own-lane leaders stay absent (inf, speed 0).
    assert (out.own_x[~present] == np.inf).all() and (out.own_v[~present] == 0.0).all()
    # No two coordinates share their draws: the shares of different coordinates / vehicles / kinds differ.
    cols = [shares["f_x"], shares["f_v"], *(shares["chain_x"].T), *(shares["chain_v"].T)]
    for i in range(len(cols)):
        for j in range(i + 1, len(cols)):
            both = np.isfinite(cols[i]) & np.isfinite(cols[j])
            assert not np.allclose(cols[i][both], cols[j][both]), (i, j)
    own_x = _normalized(out.own_x, s.own_x, want.err_own[..., 0])
    for c in range(own_x.shape[1]):
        both = present[:, c]
        for other in (shares["f_x"], *(shares["chain_x"].T)):
            assert not np.allclose(own_x[both, c], other[both])
    # Another step, seed or key draws otherwise; the same ones draw the same.
    same = measure(5, batch, 3, s, bounds)
    np.testing.assert_array_equal(same.chain_x, out.chain_x)
    for other in (measure(5, batch, 4, s, bounds), measure(6, batch, 3, s, bounds),
                  measure(5, SimpleNamespace(scenario_id=batch.scenario_id, world_key=batch.scenario_id + 1), 3, s,
                          bounds)):  # fmt: skip
        assert not np.allclose(other.chain_x, out.chain_x) and not np.allclose(other.f_v, out.f_v)
    keyed = measure(5, SimpleNamespace(scenario_id=np.zeros(len(s.f_x), int), world_key=batch.scenario_id), 3, s,
                    bounds)  # fmt: skip
    np.testing.assert_array_equal(keyed.chain_x, out.chain_x)


@pytest.mark.parametrize("share", [0.0, 0.5, 1.0])
def test_edge_share_puts_that_share_of_the_draws_at_the_bounds_ends(share):
    from safelane.shield import SensingBounds
    from safelane.sim.realworld import measure

    s = _situation(400)
    bounds = SensingBounds()
    batch = SimpleNamespace(scenario_id=np.arange(len(s.f_x)), world_key=None)
    out = measure(1, batch, 0, s, bounds, edge_share=share)
    err = bounds.apply(s).err_chain[..., 0]
    frac = _normalized(out.chain_x, s.chain_x, err)
    at_end = np.isclose(np.abs(frac), 1.0, rtol=0, atol=1e-9)
    assert at_end.mean() == pytest.approx(share, abs=0.05)
    assert (np.abs(frac) <= 1.0 + 1e-9).all()
    if share == 1.0:  # both ends, evenly
        assert (frac > 0).mean() == pytest.approx(0.5, abs=0.06)


def test_the_drawn_gap_speed_and_brake_instant_are_independent():
    """The gap, the speed spread and the brake instant are three separate uniform draws: as shares of their ranges
    no two of them coincide, and over 400 scenarios they are uncorrelated (|r| well below 0.2; the standard error of
    r for independent draws is 1/sqrt(400) = 0.05)."""
    batch, cfg = _batch(), SimConfig()
    out = with_own_lane(batch, 7, cfg, PARAMS)
    shares = {
        "gap": (out.l0_x - batch.ego_x - cfg.l0_gap_min_m) / (cfg.l0_gap_max_m - cfg.l0_gap_min_m),
        "speed": (out.l0_v - batch.ego_vx) / cfg.l0_speed_spread_mps,
        "brake": out.l0_profile_t[:, 1] / cfg.l0_brake_window_s,
    }
    names = list(shares)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            assert not np.allclose(shares[a], shares[b], rtol=0, atol=1e-6), (a, b)
            assert abs(np.corrcoef(shares[a], shares[b])[0, 1]) < 0.2, (a, b)


def _at_end(meas, true, bound):
    """Whether each drawn error is at either end of its bound (exactly, up to the subtraction's round-off)."""
    return np.isclose(np.abs(_normalized(meas, true, bound)), 1.0, rtol=0, atol=1e-9)


def test_by_default_no_draw_is_put_at_the_bounds_ends():
    """``edge_share`` defaults to 0: plain uniform draws, of which (with 53-bit draws) none lands on an end."""
    from safelane.shield import SensingBounds
    from safelane.sim.realworld import measure

    s = _situation(400)
    bounds = SensingBounds()
    out = measure(1, SimpleNamespace(scenario_id=np.arange(len(s.f_x)), world_key=None), 0, s, bounds)
    err = bounds.apply(s).err_chain[..., 0]
    frac = _normalized(out.chain_x, s.chain_x, err)
    assert not _at_end(out.chain_x, s.chain_x, err).any()
    assert (np.abs(frac) <= 1.0).all() and np.abs(frac).max() > 0.99  # inside, and spread over the whole bound


def test_the_choice_of_the_draws_put_at_the_ends_is_made_afresh_per_coordinate_and_step():
    """With ``edge_share = 0.5`` whether a draw goes to an end is its own draw for every vehicle, coordinate and step:
    any two coordinates (or one coordinate at two steps) agree on it in about half of the scenarios (for independent
    choices the agreement is Binomial(400, 0.5)/400: 0.5 ± 0.025)."""
    from safelane.shield import SensingBounds
    from safelane.sim.realworld import measure

    s = _situation(400)
    bounds = SensingBounds()
    want = bounds.apply(s)
    batch = SimpleNamespace(scenario_id=np.arange(len(s.f_x)), world_key=None)

    def ends(step):
        out = measure(1, batch, step, s, bounds, edge_share=0.5)
        masks = [_at_end(out.f_x, s.f_x, want.err_f[:, 0]), _at_end(out.f_v, s.f_v, want.err_f[:, 1])]
        masks += list(_at_end(out.chain_x, s.chain_x, want.err_chain[..., 0]).T)
        masks += list(_at_end(out.chain_v, s.chain_v, want.err_chain[..., 1]).T)
        unclipped = np.concatenate([[out.f_v > 0.0], (out.chain_v > 0.0).T])  # a clipped speed hides its draw
        return masks, unclipped.all(0)

    (now, ok_now), (later, ok_later) = ends(3), ends(4)
    ok = ok_now & ok_later
    assert ok.mean() > 0.9
    for mask in now:
        assert mask[ok].mean() == pytest.approx(0.5, abs=0.1)
    for a, b in zip(now, later, strict=True):  # the same coordinate at the next step
        assert (a == b)[ok].mean() == pytest.approx(0.5, abs=0.1)
    for i in range(len(now)):  # two coordinates (x and v of one vehicle, or two vehicles) at one step
        for j in range(i + 1, len(now)):
            assert (now[i] == now[j])[ok].mean() == pytest.approx(0.5, abs=0.1), (i, j)


def _own_share_agrees_with_a_chain_share(m):
    """Whether, in a situation with ``m`` chain vehicles and one own-lane leader, ``L0``'s position error (as a share
    of its bound) equals the position or speed error share of some chain vehicle in every scenario."""
    from safelane.shield import SensingBounds
    from safelane.sim.realworld import measure

    s = _situation(200, m, 1)
    bounds = SensingBounds()
    want = bounds.apply(s)
    out = measure(2, SimpleNamespace(scenario_id=np.arange(len(s.f_x)), world_key=None), 5, s, bounds)
    present = np.isfinite(s.own_x[:, 0])
    own = _normalized(out.own_x[present, 0], s.own_x[present, 0], want.err_own[present, 0, 0])
    chain = [_normalized(out.chain_x, s.chain_x, want.err_chain[..., 0])[present]]
    chain.append(np.where(out.chain_v > 0.0, _normalized(out.chain_v, s.chain_v, want.err_chain[..., 1]), np.nan))
    chain[1] = chain[1][present]
    same = []
    for c in np.concatenate(chain, 1).T:
        both = np.isfinite(c)
        assert both.sum() > 100
        same.append(np.allclose(c[both], own[both], rtol=0, atol=1e-9))
    return any(same)


def test_a_long_chains_measurement_errors_are_independent_of_the_own_lane_leaders():
    """With 31 chain vehicles (the paper's campaigns use up to 11) no chain vehicle's position or speed error is
    ``L0``'s position error: every coordinate has its own draw."""
    assert not _own_share_agrees_with_a_chain_share(31)


def test_a_chain_of_32_vehicles_measurement_errors_are_independent_of_the_own_lane_leaders():
    """``n_leaders`` is any non-negative integer (``sim.scenario``): a 32-vehicle chain is a valid world, and its
    vehicles' measurement errors must be drawn apart from ``L0``'s as well (the 32nd and later shared ``L0``'s draws
    until the chain's columns past the 31st got a counter of their own)."""
    assert not _own_share_agrees_with_a_chain_share(32)


def test_in_a_50_vehicle_chain_no_two_measured_coordinates_share_a_draw():
    """Every position and speed of F, a 50-vehicle chain and two own-lane leaders is off by a draw of its own: no
    two coordinates' error shares (error / bound) agree in every scenario. A chain this long reaches past the own
    lane's counter slots (from the 32nd vehicle on), where its columns draw on a counter of their own."""
    from safelane.shield import SensingBounds
    from safelane.sim.realworld import measure

    s = _situation(120, 50, 2)
    s = dataclasses.replace(s, chain_v=s.chain_v + 50.0, own_v=s.own_v + 50.0, f_v=s.f_v + 50.0)  # never clipped at 0
    bounds = SensingBounds()
    want = bounds.apply(s)
    out = measure(3, SimpleNamespace(scenario_id=np.arange(len(s.f_x)), world_key=None), 4, s, bounds)
    present = np.isfinite(s.own_x).all(1)
    cols = [
        _normalized(out.f_x, s.f_x, want.err_f[:, 0])[:, None],
        _normalized(out.f_v, s.f_v, want.err_f[:, 1])[:, None],
    ]
    pairs = (("chain_x", "err_chain", 0), ("chain_v", "err_chain", 1), ("own_x", "err_own", 0), ("own_v", "err_own", 1))
    for name, err, i in pairs:
        cols.append(_normalized(getattr(out, name), getattr(s, name), getattr(want, err)[..., i]))
    shares = np.concatenate(cols, 1)[present]
    assert shares.shape[1] == 2 + 100 + 4 and present.sum() > 40 and np.isfinite(shares).all()
    assert (np.abs(shares) <= 1.0).all()
    # Equal draws give shares equal up to round-off (~1e-13 here); independent ones never agree to 1e-6 in every
    # scenario. Sort the columns by their rounded values, then compare neighbours.
    rounded = np.round(shares, 6)
    ordered = rounded.T[np.lexsort(rounded[::-1])]
    assert not (ordered[1:] == ordered[:-1]).all(1).any(), "two coordinates share their draws"


def _at_rest(x):
    """Motions over one period of vehicles at rest at ``x`` (longitudinal and lateral)."""
    x = np.asarray(x, float)
    return Motion.constant(x, 0.0 * x, 0.0 * x, DT)


def test_own_lane_checks_at_the_edges_of_the_footprint_and_of_the_margin():
    """The ego at rest at ``x = 0`` in its own lane (``y = 0 < w_v`` throughout), ``L0`` at rest at the gap ``g``
    (ahead for ``g > 0``, behind for ``g < 0``), so ``x0 − x = g`` at every instant. Collision: ``|g| < length``
    (touching footprints do not overlap); violation: ``|g| < p_m`` up to the simulator's 1 nm tolerance, i.e.
    ``p_m − 1e-9 > g > −p_m + 1e-9`` (a gap of exactly ``p_m`` is kept, and so is one of exactly ``p_m − 1 nm``)."""
    length, p_m = PARAMS.vehicle_length, PARAMS.p_m
    edge = p_m - 1e-9
    below = np.nextafter(edge, 0.0)  # one ulp inside the tolerance
    cases = [  # (gap, collided, violated)
        (0.0, True, True),
        (2.0, True, True),
        (np.nextafter(length, 0.0), True, True),
        (length, False, True),
        (-length, False, True),
        (-np.nextafter(length, 0.0), True, True),
        (6.5, False, True),
        (-6.5, False, True),
        (below, False, True),
        (-below, False, True),
        (edge, False, False),
        (-p_m + 1e-9, False, False),
        (p_m, False, False),
        (-p_m, False, False),
        (20.0, False, False),
        (-20.0, False, False),
    ]
    gaps = np.array([c[0] for c in cases])
    n = len(cases)
    lon, lat, l0 = _at_rest(np.zeros(n)), _at_rest(np.zeros(n)), _at_rest(gaps)
    present, completed = np.ones(n, bool), np.zeros(n, bool)
    collided, violated, min_gap = own_lane_checks(PARAMS, lon, lat, None, l0, present, completed)
    np.testing.assert_array_equal(min_gap, gaps)  # the gap between two vehicles at rest, exactly
    np.testing.assert_array_equal(collided, [c[1] for c in cases])
    np.testing.assert_array_equal(violated, [c[2] for c in cases])
    # Once the lane change has completed, p_m no longer counts; a collision still does.
    collided2, violated2, _ = own_lane_checks(PARAMS, lon, lat, None, l0, present, np.ones(n, bool))
    np.testing.assert_array_equal(collided2, collided)
    assert not violated2.any()


def test_own_lane_checks_take_each_rows_motion_whatever_the_sizes_of_the_groups():
    """Rows on the plan are checked along the plan's motion, the others along their command's; absent ``L0``s count
    nothing. Every ego is at rest in its own lane and ``L0`` at rest 3 m ahead of where the ego's motion puts it
    (a collision: 3 < length), while the command's motion of a planned row is 50 m behind (no collision there).
    Groups of one row and an empty plan group (its only row absent) are checked like any other."""
    n = 3
    l0 = _at_rest(np.full(n, 3.0))
    lat = _at_rest(np.zeros(n))

    def plan_of(rows):
        return rows, _at_rest(np.zeros(len(rows))), _at_rest(np.zeros(len(rows)))

    # Plan rows 0 and 1 with row 0 absent: the plan's group is row 1 alone; the rest is row 2 alone (its command
    # at x = 0 collides).
    lon = _at_rest(np.array([-50.0, -50.0, 0.0]))
    present = np.array([False, True, True])
    collided, violated, min_gap = own_lane_checks(
        PARAMS, lon, lat, plan_of(np.array([0, 1])), l0, present, np.zeros(n, bool)
    )
    np.testing.assert_array_equal(collided, [False, True, True])
    np.testing.assert_array_equal(violated, [False, True, True])
    np.testing.assert_array_equal(min_gap, [np.inf, 3.0, 3.0])
    # The plan's only row absent (an empty group), the other rows checked along their commands.
    lon = _at_rest(np.array([0.0, 0.0, -50.0]))
    present = np.array([False, True, True])
    plan = plan_of(np.array([0]))
    collided, violated, min_gap = own_lane_checks(PARAMS, lon, lat, plan, l0, present, np.zeros(n, bool))
    np.testing.assert_array_equal(collided, [False, True, False])
    np.testing.assert_array_equal(violated, [False, True, False])
    np.testing.assert_array_equal(min_gap, [np.inf, 3.0, 53.0])
    # A batch of one row.
    one, ahead = _at_rest(np.zeros(1)), _at_rest(np.full(1, 3.0))
    collided, violated, min_gap = own_lane_checks(
        PARAMS, _at_rest(np.full(1, -50.0)), one, None, ahead, np.ones(1, bool), np.zeros(1, bool)
    )
    assert not collided[0] and not violated[0] and min_gap[0] == 53.0
    collided, _, min_gap = own_lane_checks(PARAMS, one, one, None, ahead, np.ones(1, bool), np.zeros(1, bool))
    assert collided[0] and min_gap[0] == 3.0


@pytest.mark.parametrize("edge_share", [0.0, 0.5])
def test_measure_draws_each_coordinate_from_its_documented_counter(edge_share):
    """Same seed, same numbers: every measured coordinate is ``truth + bound * (2u - 1)`` (speeds floored at 0) with
    ``u`` the counter-based uniform of its documented slot — F at ``_SLOT_NOISE`` (+1 for the speed), chain vehicle
    ``j`` at ``_SLOT_NOISE + 2 + 2j`` (from the 32nd on, the same slot with one more counter element, 1), the own lane's
    ``j`` at ``_SLOT_NOISE + 64 + 2j``; with ``edge_share`` the draw goes to the nearer end where a second uniform
    (one more counter element, 9) falls below it. The falsifier replays a campaign's row on this contract."""
    from safelane.shield import SensingBounds
    from safelane.sim.realworld import _SLOT_NOISE, measure
    from safelane.sim.rng import counter_uniform

    seed, step, b = 9, 6, 40
    s = _situation(b, 40, 2)
    s = dataclasses.replace(s, chain_v=s.chain_v + 50.0, own_v=s.own_v + 50.0, f_v=s.f_v + 50.0)  # never floored
    bounds = SensingBounds()
    want = bounds.apply(s)
    sid = np.arange(b) + 100
    out = measure(seed, SimpleNamespace(scenario_id=sid, world_key=None), step, s, bounds, edge_share=edge_share)

    def u(*counters):
        draw = counter_uniform(seed, sid, step, *counters)
        if edge_share > 0.0:
            draw = np.where(counter_uniform(seed, sid, step, *counters, 9) < edge_share, np.round(draw), draw)
        return draw

    np.testing.assert_array_equal(out.f_x, s.f_x + want.err_f[:, 0] * (2.0 * u(_SLOT_NOISE) - 1.0))
    np.testing.assert_array_equal(out.f_v, s.f_v + want.err_f[:, 1] * (2.0 * u(_SLOT_NOISE + 1) - 1.0))
    for j in (0, 7, 30, 31, 39):
        extra = (1,) if j >= 31 else ()
        slot = _SLOT_NOISE + 2 + 2 * j
        np.testing.assert_array_equal(out.chain_x[:, j],
                                      s.chain_x[:, j] + want.err_chain[:, j, 0] * (2.0 * u(slot, *extra) - 1.0))
        np.testing.assert_array_equal(out.chain_v[:, j],
                                      s.chain_v[:, j] + want.err_chain[:, j, 1] * (2.0 * u(slot + 1, *extra) - 1.0))
    present = np.isfinite(s.own_x[:, 1])
    slot = _SLOT_NOISE + 64 + 2
    np.testing.assert_array_equal(out.own_x[present, 1], (s.own_x[:, 1] + want.err_own[:, 1, 0]
                                                          * (2.0 * u(slot) - 1.0))[present])  # fmt: skip
    np.testing.assert_array_equal(out.own_v[present, 1], (s.own_v[:, 1] + want.err_own[:, 1, 1]
                                                          * (2.0 * u(slot + 1) - 1.0))[present])  # fmt: skip
    assert present.sum() > 10
