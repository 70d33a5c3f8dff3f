"""The simulator's per-period checks (``sim/checks.py``) against an independent dense-time reference.

The reference knows nothing of knots, filters or closed forms: each vehicle's position is integrated segment by
segment from its accelerations (a braking vehicle stops and stays at rest; the ego's lateral motion is not
clamped), and every gap is evaluated on a grid of 4001 instants over the period plus the exact instants where the
ego's lateral position crosses each level (so the windows' closures are sampled at their ends). Gaps are C¹ in
time (speeds are continuous), so the grid's minimum is within ``max|gap''| h²/8 < 2e-9 m`` of the exact one;
rows whose outcome lies within 1e-7 m of a threshold are left out of the boolean comparison (there are few).

What is checked, per the docstrings of :func:`ego_checks` and :func:`lane_checks`:

* collisions (``|dx| < vehicle_length`` while the ego is beyond the overlap level; between target-lane vehicles,
  ``gap < vehicle_length``) and ``p_m`` / margin violations (beyond the conflict level; ``gap < margin``), exact in
  continuous time;
* the reported minimum gaps: never below the exact minimum over the window, never above the gap sampled at the
  period's ends; exact where the pair came within its margin; the end samples where the documented bound
  (``|Δv| dt + (a_max,ego + a_max,others) dt²/2``, resp. ``|Δv| dt + a_max dt²``) shows it stayed farther;
  and the running minimum carried over.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.sim.checks import ego_checks, lane_checks, lane_pairs
from safelane.sim.kinematics import Fleet, Motion

#: The checks and motions divide only where it is safe (or under errstate): no floating-point warning escapes.
pytestmark = pytest.mark.filterwarnings("error")

PARAMS = Params()
DT = PARAMS.dt
CONFLICT = PARAMS.y_safe + 1e-9
OVERLAP = PARAMS.lane_width - PARAMS.vehicle_width
GRID = np.linspace(0.0, DT, 4001)
AMBIGUOUS = 1e-7


def trajectory(x0, v0, starts, accs, t, clamp=True):
    """Position and speed at the times ``t`` of a vehicle with acceleration ``accs[i]`` from ``starts[i]``
    (``starts[0] = 0``), integrated segment by segment; with ``clamp`` it stops at rest and stays there while its
    acceleration is not positive."""
    t = np.asarray(t, float)
    xs, vs = np.empty_like(t), np.empty_like(t)
    x, v = float(x0), float(v0)
    ends = [*starts[1:], np.inf]
    for start, end, a in zip(starts, ends, accs, strict=True):
        sel = (t >= start) & (t < end) if np.isfinite(end) else t >= start
        xs[sel], vs[sel] = _kin(x, v, a, t[sel] - start, clamp)
        if np.isfinite(end):
            x, v = (float(q[0]) for q in _kin(x, v, a, np.array([end - start]), clamp))
    return xs, vs


def _kin(x, v, a, tau, clamp):
    if clamp and a < 0.0:
        t_stop = v / -a
        m = np.minimum(tau, t_stop)
        return x + v * m + 0.5 * a * m * m, np.where(tau >= t_stop, 0.0, v + a * tau)
    return x + v * tau + 0.5 * a * tau * tau, v + a * tau


def crossings(y0, vy0, starts, accs, level):
    """Instants in ``(0, DT)`` where an unclamped piecewise-quadratic lateral motion equals ``level``."""
    out = []
    y, vy = y0, vy0
    ends = [*starts[1:], DT]
    for start, end, a in zip(starts, ends, accs, strict=True):
        c = y - level
        if a == 0.0:
            roots = [-c / vy] if vy != 0.0 else []
        else:
            disc = vy * vy - 2.0 * a * c
            roots = [] if disc < 0.0 else [(-vy - np.sqrt(disc)) / a, (-vy + np.sqrt(disc)) / a]
        out += [start + r for r in roots if 0.0 < r < end - start]
        h = end - start
        y, vy = y + vy * h + 0.5 * a * h * h, vy + a * h
    return out


def _accel(rng, shape, lo=-PARAMS.a_x_d, hi=PARAMS.a_x_a):
    a = rng.uniform(lo, hi, shape)
    pick = rng.uniform(size=shape)
    return np.where(pick < 0.1, 0.0, np.where(pick < 0.2, lo, np.where(pick < 0.25, hi, a)))


def _plan_segments(rng, x0, v0, y0, vy0, knots=None):
    """A plan over the period: 4 segments between random knots; longitudinal accelerations within the ego's
    limits, with a stop exactly at a knot where a segment would reverse; lateral accelerations within ±a_y_m."""
    if knots is None:
        knots = np.concatenate([[0.0], np.sort(rng.uniform(0.0, DT, 3)), [DT]])
    ax = list(_accel(rng, 4))
    ay = list(rng.uniform(-PARAMS.a_y_m, PARAMS.a_y_m, 4))
    v = v0
    for i in range(4):
        h = knots[i + 1] - knots[i]
        if v + ax[i] * h < 0.0:
            ax[i] = -v / h if h > 0.0 else 0.0  # stops exactly at the knot
        v = max(v + ax[i] * h, 0.0) if v + ax[i] * h > 0.0 else 0.0
    xs, vs = trajectory(x0, v0, knots[:-1], ax, knots)
    ys, vys = trajectory(y0, vy0, knots[:-1], ay, knots, clamp=False)
    return knots, ax, ay, xs, vs, ys, vys


def scenarios(seed, bsz=240, k=4, switched=False, planned=False):
    """Random periods: ego mid lane change near both lateral levels, F behind, leaders ahead (some overlapping,
    some at rest, some invalid), the ego and the others' accelerations at and inside the limits."""
    rng = np.random.default_rng(seed)
    ex = rng.uniform(-20.0, 20.0, bsz)
    evx = rng.uniform(0.0, 32.0, bsz)
    evx[rng.uniform(size=bsz) < 0.1] = 0.0
    ey = rng.uniform(0.3, 2.6, bsz)
    evy = rng.uniform(-1.5, 1.5, bsz)
    eay = rng.uniform(-PARAMS.a_y_m, PARAMS.a_y_m, bsz)
    eax = _accel(rng, bsz)
    offsets = np.stack([-rng.uniform(0.0, 22.0, bsz)] + [rng.uniform(0.0, 22.0, bsz) for _ in range(k - 1)], 1)
    offsets[:, 2:] = offsets[:, 1:2] + np.cumsum(offsets[:, 2:], 1)
    x = np.asfortranarray(ex[:, None] + offsets)
    v = np.asfortranarray(np.maximum(evx[:, None] + rng.normal(0.0, 4.0, (bsz, k)), 0.0))
    v[rng.uniform(size=(bsz, k)) < 0.15] = 0.0
    v[rng.uniform(size=(bsz, k)) < 0.1] = 0.4  # stops inside the period when braking hard
    acc = np.asfortranarray(_accel(rng, (bsz, k)))
    segs = [[([0.0], [acc[i, j]]) for j in range(k)] for i in range(bsz)]
    if switched:
        t_sw = np.where(rng.uniform(size=(bsz, k)) < 0.5, rng.uniform(0.0, DT, (bsz, k)), DT)
        a2 = _accel(rng, (bsz, k))
        others = Fleet.switched(x, v, acc, t_sw, a2, DT)
        for i, j in zip(*np.nonzero(t_sw < DT), strict=True):
            segs[i][j] = ([0.0, t_sw[i, j]], [acc[i, j], a2[i, j]])
    else:
        others = Fleet.constant(x, v, acc, DT)
    valid = rng.uniform(size=(bsz, k)) < 0.9
    human = rng.uniform(size=(bsz, k)) < 0.3
    lon = Motion.constant(ex, evx, eax, DT)
    lat = Motion.free(ey, evy, eay, DT)
    ego = [(([0.0], [eax[i]]), ([0.0], [eay[i]])) for i in range(bsz)]
    plan = None
    if planned:
        rows = np.flatnonzero(rng.uniform(size=bsz) < 0.35)
        parts = [_plan_segments(rng, ex[i], evx[i], ey[i], evy[i]) for i in rows]
        knots = np.stack([p[0] for p in parts])
        plan_lon = Motion.from_samples(knots, np.stack([p[3] for p in parts]), np.stack([p[4] for p in parts]))
        plan_lat = Motion.from_samples(knots, np.stack([p[5] for p in parts]), np.stack([p[6] for p in parts]))
        plan = (rows, plan_lon, plan_lat)
        for i, p in zip(rows, parts, strict=True):
            ego[i] = ((list(p[0][:-1]), p[1]), (list(p[0][:-1]), p[2]))
    running = np.where(rng.uniform(size=bsz) < 0.3, rng.uniform(0.0, 15.0, bsz), np.inf)
    s = SimpleNamespace(
        x=x, v=v, ego=(ex, ey, evx, evy), min_gap_f=running.copy(), min_gap_l1=np.roll(running, 1).copy()
    )
    b = SimpleNamespace(valid=valid, human=human)
    world = dict(ex=ex, evx=evx, ey=ey, evy=evy, x=x, v=v, segs=segs, ego=ego)
    return b, s, lon, lat, others, plan, world


def _ego_reference(i, world, others):
    """Per vehicle of row ``i``: the exact (min, max) of the gap over the closures of both windows, the gap at the
    period's ends, and whether the ego is beyond the conflict level at either end."""
    (sx, ax), (sy, ay) = world["ego"][i]
    cross = [crossings(world["ey"][i], world["evy"][i], sy, ay, lvl) for lvl in (CONFLICT, OVERLAP)]
    t = np.unique(np.concatenate([GRID, *map(np.array, cross)]))
    ex, _ = trajectory(world["ex"][i], world["evx"][i], sx, ax, t)
    ey, _ = trajectory(world["ey"][i], world["evy"][i], sy, ay, t, clamp=False)
    out = []
    for j in range(world["x"].shape[1]):
        starts, accs = world["segs"][i][j]
        gap = trajectory(world["x"][i, j], world["v"][i, j], starts, accs, t)[0] - ex
        ext = []
        for lvl, cr in zip((CONFLICT, OVERLAP), cross, strict=True):
            win = (ey > lvl) | np.isin(t, np.array(cr))
            ext.append((gap[win].min(initial=np.inf), gap[win].max(initial=-np.inf)))
        out.append(dict(c=ext[0], o=ext[1], ends=(gap[0], gap[-1]), in_end=(ey[0] > CONFLICT, ey[-1] > CONFLICT)))
    return out


def _check_ego(b, s, lon, lat, others, plan, world):
    running_f, running_l1 = s.min_gap_f.copy(), s.min_gap_l1.copy()
    collided, violated, min_f, min_l1 = ego_checks(b, PARAMS, s, lon, lat, others, CONFLICT, OVERLAP, plan)
    a_bound = max(PARAMS.a_x_a, PARAMS.a_x_d) + others.row_max_abs_acc()
    counts = dict(collided=0, violated=0, clean=0, skipped=0, exact=0, sampled=0)
    for i in range(len(collided)):
        ref = _ego_reference(i, world, others)
        col = viol = False
        ambiguous = False
        for j, r in enumerate(ref):
            if not b.valid[i, j]:
                continue
            (c_lo, c_hi), (o_lo, o_hi) = r["c"], r["o"]
            edges = (o_lo - PARAMS.vehicle_length, o_hi + PARAMS.vehicle_length,
                     c_lo - PARAMS.p_m + 1e-9, c_hi + PARAMS.p_m - 1e-9)  # fmt: skip
            ambiguous |= min(abs(e) for e in edges) < AMBIGUOUS
            col |= o_lo < PARAMS.vehicle_length and o_hi > -PARAMS.vehicle_length
            viol |= c_lo < PARAMS.p_m - 1e-9 and c_hi > -PARAMS.p_m + 1e-9
        if ambiguous:
            counts["skipped"] += 1
        else:
            assert (bool(collided[i]), bool(violated[i])) == (col, viol), i
            counts["collided"] += col
            counts["violated"] += viol
            counts["clean"] += not viol
        for j, sign, got, running in ((0, -1.0, min_f, running_f), (1, 1.0, min_l1, running_l1)):
            if not b.valid[i, j]:
                assert got[i] == running[i]
                continue
            r = ref[j]
            exact = sign * (r["c"][0] if sign > 0 else r["c"][1])  # the window's minimum of the signed gap
            sampled = min(
                (sign * g for g, inside in zip(r["ends"], r["in_end"], strict=True) if inside), default=np.inf
            )
            lo, hi = min(running[i], exact), min(running[i], sampled)
            assert lo - 1e-7 <= got[i] <= hi + 1e-7, (i, j)
            d0 = world["x"][i, j] - world["ex"][i]
            reach = abs(world["v"][i, j] - world["evx"][i]) * DT + 0.5 * a_bound[i] * DT * DT
            if exact < PARAMS.p_m:  # came within p_m: must be exact
                assert got[i] == pytest.approx(lo, abs=1e-7), (i, j)
                counts["exact"] += exact < sampled - 1e-6
            elif abs(d0) - reach > PARAMS.p_m + 1e-3:  # stayed farther by the bound: the end samples
                assert got[i] == hi, (i, j)
                counts["sampled"] += sampled > exact + 1e-6 and running[i] > exact
    return counts


@pytest.mark.parametrize(("seed", "switched", "planned"), [(1, False, False), (2, True, False), (3, False, True),
                                                          (4, True, True)])  # fmt: skip
def test_ego_checks_match_the_dense_reference(seed, switched, planned):
    counts = _check_ego(*scenarios(seed, switched=switched, planned=planned))
    # The draws reach every outcome: collisions, violations without collision, clean rows, exact minimum gaps below
    # the end samples, and far pairs whose end samples lie above a mid-period dip.
    assert counts["collided"] >= 5 and counts["violated"] > counts["collided"] and counts["clean"] >= 20, counts
    assert counts["exact"] >= 2 and counts["sampled"] >= 3, counts
    assert counts["skipped"] <= 5, counts


def _lane_reference(i, world, b, margin):
    k = world["x"].shape[1]
    pos = [trajectory(world["x"][i, j], world["v"][i, j], *world["segs"][i][j], GRID)[0] for j in range(k)]
    out = []
    for j in range(k - 1):
        if not (b.valid[i, j] and b.valid[i, j + 1]):
            out.append(None)
            continue
        gap = pos[j + 1] - pos[j]
        out.append((gap.min(), min(gap[0], gap[-1]), margin[i, j], gap.max() == gap.min()))
    return out


@pytest.mark.parametrize(("seed", "switched"), [(5, False), (6, True)])
def test_lane_checks_match_the_dense_reference(seed, switched):
    b, *_, world = scenarios(seed, bsz=400, switched=switched)
    x, v = world["x"], world["v"]
    # Closer target-lane pairs than the ego's draws: some overlapping, some at rest exactly at or near the margin.
    rng = np.random.default_rng(seed + 50)
    x[:, 1:] = x[:, :1] + np.cumsum(rng.uniform(3.0, 18.0, (len(x), x.shape[1] - 1)), 1)
    rest = rng.uniform(size=len(x)) < 0.15
    v[rest, :2] = 0.0
    x[rest, 1] = x[rest, 0] + np.where(rng.uniform(size=rest.sum()) < 0.5, PARAMS.p_m, PARAMS.p_m + 0.03)
    segs = world["segs"]
    acc = np.asfortranarray([[seg[1][0] for seg in row] for row in segs])
    if switched:
        t_sw = np.array([[seg[0][1] if len(seg[0]) > 1 else DT for seg in row] for row in segs])
        a2 = np.array([[seg[1][1] if len(seg[1]) > 1 else 0.0 for seg in row] for row in segs])
        others = Fleet.switched(np.asfortranarray(x), np.asfortranarray(v), acc, t_sw, a2, DT)
    else:
        others = Fleet.constant(np.asfortranarray(x), np.asfortranarray(v), acc, DT)
    valid, margin = lane_pairs(b, PARAMS)
    np.testing.assert_array_equal(margin, np.where(b.human[:, :-1], PARAMS.p_m_human, PARAMS.p_m))
    np.testing.assert_array_equal(valid, b.valid[:, 1:] & b.valid[:, :-1])
    collided, violated, ratio = lane_checks(b, PARAMS, others)
    given = lane_checks(b, PARAMS, others, (valid, margin))
    for g, w in zip(given, (collided, violated, ratio), strict=True):
        np.testing.assert_array_equal(g, w)
    a_max = others.row_max_abs_acc()
    counts = dict(collided=0, violated=0, exact=0, sampled=0, skipped=0)
    for i in range(len(x)):
        ref = [r for r in _lane_reference(i, world | dict(x=x, v=v), b, margin) if r is not None]
        moving = [r for r in ref if not r[3]]  # a constant gap (both at rest) is exact in the reference
        lows = [r[0] - r[2] + 1e-9 for r in moving] + [r[0] - PARAMS.vehicle_length for r in moving]
        if any(abs(e) < AMBIGUOUS for e in lows):
            counts["skipped"] += 1
        else:
            col = any(r[0] < PARAMS.vehicle_length for r in ref)
            viol = any(r[0] < r[2] - 1e-9 for r in ref)
            assert (bool(collided[i]), bool(violated[i])) == (col, viol), i
            counts["collided"] += col
            counts["violated"] += viol
        lo, hi = np.inf, np.inf
        pairs = [j for j in range(x.shape[1] - 1) if valid[i, j]]
        for j, (exact, sampled, m, _) in zip(pairs, ref, strict=True):
            far = (x[i, j + 1] - x[i, j]) - abs(v[i, j + 1] - v[i, j]) * DT - a_max[i] * DT * DT > m + 1e-3
            # Far by the documented bound: the end samples; within the margin: exact; in between: either.
            lo = min(lo, (sampled if far else exact) / m)
            hi = min(hi, (exact if exact < m and not far else sampled) / m)
            counts["sampled"] += far and sampled > exact + 1e-6
            counts["exact"] += exact < m and exact < sampled - 1e-6
        assert lo - 1e-9 <= ratio[i] <= hi + 1e-9, i
    assert counts["collided"] >= 5 and counts["violated"] > counts["collided"], counts
    assert counts["exact"] >= 2 and counts["sampled"] >= 2 and counts["skipped"] <= 5, counts
