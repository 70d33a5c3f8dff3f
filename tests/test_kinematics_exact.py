"""``sim/kinematics.py`` against independent references: the switched fleet and its knots against segment-by-segment
integration (``trajectory`` of ``test_sim_checks_reference``), the acceleration bounds against a brute-force maximum,
crossing instants against the quadratic formula's defining property, extrema against dense sampling."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.sim.kinematics import (
    Fleet,
    Motion,
    Switch,
    crossing_knots,
    extrema,
    gap_extrema,
    windowed_gap_extrema,
)
from test_sim_checks_reference import trajectory

#: The checks and motions divide only where it is safe (or under errstate): no floating-point warning escapes.
pytestmark = pytest.mark.filterwarnings("error")

PARAMS = Params()
DT = PARAMS.dt
TQ = np.linspace(0.0, DT, 1001)


def _switched_draws(seed, n=250):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-50.0, 50.0, n)
    v = rng.uniform(0.0, 30.0, n)
    v[rng.uniform(size=n) < 0.2] = 0.0  # at rest: stays unless a2 > 0
    v[rng.uniform(size=n) < 0.2] = 0.3  # stops inside the period when braking
    a1 = rng.uniform(-8.0, 2.5, n)
    a2 = rng.uniform(-8.0, 2.5, n)
    a1[rng.uniform(size=n) < 0.1] = 0.0
    t_sw = np.where(rng.uniform(size=n) < 0.7, rng.uniform(0.0, DT, n), rng.choice([DT, 2 * DT], n))
    t_sw[:5] = 0.0  # a switch at the period's start
    return x, v, a1, t_sw, a2


@pytest.mark.parametrize("seed", [0, 1])
def test_switched_fleet_matches_segment_by_segment_integration(seed):
    x, v, a1, t_sw, a2 = _switched_draws(seed)
    fleet = Fleet.switched(x, v, a1, t_sw, a2, DT)
    assert fleet.switching is fleet.switch.mask
    np.testing.assert_array_equal(fleet.switching, t_sw < DT)
    assert fleet.switch.t.dtype == np.float64
    np.testing.assert_array_equal(fleet.switch.t, np.where(t_sw < DT, t_sw, DT))  # "dt where none"
    m = fleet.motion(...)
    assert m.t.shape == (len(x), 5) and (np.diff(m.t, axis=-1) >= 0.0).all()
    assert (m.t[:, 0] == 0.0).all() and (m.t[:, -1] == DT).all()
    xq, vq = m.at(np.broadcast_to(TQ, (len(x), TQ.size)))
    for i in range(len(x)):
        segs = ([0.0, t_sw[i]], [a1[i], a2[i]]) if t_sw[i] < DT else ([0.0], [a1[i]])
        ref_x, ref_v = trajectory(x[i], v[i], *segs, TQ)
        np.testing.assert_allclose(xq[i], ref_x, rtol=0, atol=1e-9, err_msg=str(i))
        np.testing.assert_allclose(vq[i], ref_v, rtol=0, atol=1e-9, err_msg=str(i))
        assert fleet.x_end[i] == pytest.approx(ref_x[-1], abs=1e-9)
        assert fleet.v_end[i] == pytest.approx(ref_v[-1], abs=1e-9)
        assert (fleet.v_end[i] == 0.0) == (ref_v[-1] <= 1e-12)
    assert (vq >= 0.0).all()
    np.testing.assert_array_equal(fleet.end[0], fleet.x_end)
    np.testing.assert_array_equal(fleet.end[1], fleet.v_end)
    # Some at rest start moving after the switch, some stop in either segment.
    assert ((v == 0.0) & (t_sw < DT) & (a2 > 0.0)).any() and (fleet.v_end == 0.0).sum() > 20


def test_switched_without_any_switch_is_constant():
    x, v, a1, _, a2 = _switched_draws(3, 50)
    fleet = Fleet.switched(x, v, a1, np.full(50, DT), a2, DT)
    const = Fleet.constant(x, v, a1, DT)
    assert fleet.switch is None and fleet.switching is None
    for f in ("x", "v", "acc", "t_stop", "x_end", "v_end"):
        np.testing.assert_array_equal(getattr(fleet, f), getattr(const, f))


def test_acceleration_bounds_are_the_largest_magnitude_in_any_segment():
    x, v, a1, t_sw, a2 = _switched_draws(4, 60)
    x, v, a1, t_sw, a2 = (q.reshape(6, 10) for q in (x, v, a1, t_sw, a2))
    fleet = Fleet.switched(x, v, a1, t_sw, a2, DT)
    # Brute force over what each vehicle actually does: the acceleration at every sampled instant (0 at rest).
    _, vq = fleet.motion(...).at(np.broadcast_to(TQ, (6, 10, TQ.size)))
    seen = np.abs(np.diff(vq, axis=-1) / np.diff(TQ)).max(-1)  # ≈ |a| on each vehicle's segments
    row = fleet.row_max_abs_acc()
    assert row.shape == (6,)
    np.testing.assert_array_less(seen.max(1) - 1e-6, row)  # an upper bound of what is driven …
    # What is driven: a1 unless at rest and not accelerating; after a switch, a2 unless at rest there (speed from
    # the reference integration) and not accelerating.
    draws = zip(x.ravel(), v.ravel(), a1.ravel(), t_sw.ravel(), strict=True)
    v_at_switch = np.array([trajectory(x0, v0, [0.0], [a], np.array([min(ts, DT)]))[1][0] for x0, v0, a, ts in draws])
    v_at_switch = v_at_switch.reshape(v.shape)
    acc_on = np.where((v > 0.0) | (a1 > 0.0), np.abs(a1), 0.0)
    acc_on = np.maximum(acc_on, np.where((t_sw < DT) & ((v_at_switch > 0.0) | (a2 > 0.0)), np.abs(a2), 0.0))
    np.testing.assert_allclose(row, acc_on.max(1), rtol=0, atol=0)  # … and exactly the largest one used
    assert fleet.max_abs_acc == row.max()
    const = Fleet.constant(x, v, a1, DT)
    np.testing.assert_array_equal(const.row_max_abs_acc(), np.abs(const.acc).max(1))
    assert const.max_abs_acc == np.abs(const.acc).max()
    empty = Fleet.constant(np.zeros((2, 0)), np.zeros((2, 0)), np.zeros((2, 0)), DT)
    np.testing.assert_array_equal(empty.row_max_abs_acc(), [0.0, 0.0])
    assert empty.max_abs_acc == 0.0


def test_switch_of_a_vehicle_at_rest_only_by_a_positive_acceleration():
    # At rest, braking, then a2: it stays at rest for a2 <= 0 and starts from rest at the switch for a2 > 0.
    x, v = np.zeros(3), np.zeros(3)
    fleet = Fleet.switched(x, v, np.full(3, -8.0), np.full(3, 0.04), np.array([-3.0, 0.0, 2.0]), DT)
    np.testing.assert_array_equal(fleet.x_end[:2], 0.0)
    assert fleet.x_end[2] == pytest.approx(0.5 * 2.0 * 0.06**2, abs=1e-15)
    assert fleet.v_end[2] == pytest.approx(0.12, abs=1e-15)
    assert fleet.max_abs_acc == 2.0  # the braking of a vehicle at rest is not driven: only the 2 m/s² after


def test_a_vehicle_that_stops_before_or_at_its_switch_is_exactly_at_rest():
    """``v + a (v / −a)`` rounds to +6.9e-18 for this pair: a stop inside the first segment must still leave the
    vehicle exactly at rest (speed 0.0, which the lane checks' "at rest all period" test relies on), whether the
    switch comes after the stop or exactly at it."""
    v, a = np.array([0.05991188490091204]), np.array([-7.002845080054524])
    assert v + a * (v / -a) != 0.0
    t_stop = Fleet.constant(np.zeros(1), v, a, DT).t_stop
    for t_sw in (np.array([0.05]), t_stop):
        fleet = Fleet.switched(np.zeros(1), v, a, t_sw, np.zeros(1), DT)
        assert fleet.switch.v[0] == 0.0 and fleet.v_end[0] == 0.0
        assert fleet.x_end[0] == pytest.approx(v[0] ** 2 / (-2.0 * a[0]), rel=1e-12)
    # The same stop in the second segment (cruising until 0.01 s, then braking).
    fleet = Fleet.switched(np.zeros(1), v, np.zeros(1), np.array([0.01]), a, DT)
    assert fleet.v_end[0] == 0.0
    assert fleet.x_end[0] == pytest.approx(v[0] * 0.01 + v[0] ** 2 / (-2.0 * a[0]), rel=1e-12)


def test_from_samples_with_repeated_knots():
    """Zero-length segments (repeated knots) get acceleration 0; the motion between the others is exact."""
    t = np.array([[0.0, 0.03, 0.03, 0.07, DT]])
    accs = [1.5, -4.0, 2.0]  # on [0, .03), [.03, .07), [.07, dt]
    xk, vk = trajectory(2.0, 10.0, [0.0, 0.03, 0.07], accs, t[0])
    m = Motion.from_samples(t, xk[None], vk[None])
    np.testing.assert_allclose(m.acc[0], [1.5, 0.0, -4.0, 2.0], rtol=0, atol=1e-9)
    ref = trajectory(2.0, 10.0, [0.0, 0.03, 0.07], accs, TQ)
    xq, vq = m.at(TQ[None, :])
    np.testing.assert_allclose(xq[0], ref[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(vq[0], ref[1], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(m.end[0], xk[None, -1])
    np.testing.assert_array_equal(m.end[1], vk[None, -1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_crossing_knots_split_the_period_where_the_sign_changes(seed):
    """Between consecutive returned knots ``x − level`` keeps one sign (checked on a dense grid inside each
    interval), and every returned instant that is not one of the motion's knots is a root."""
    rng = np.random.default_rng(seed)
    n, level = 300, 1.0
    y0 = level + rng.uniform(-0.12, 0.12, n)
    y0[:10] = level  # starting on the level
    vy = rng.uniform(-1.5, 1.5, n)
    vy[10:20] = 0.0  # parallel: a linear or no crossing
    ay = rng.uniform(-1.5, 1.5, n)
    ay[20:40] = 0.0
    m = Motion.free(y0, vy, ay, DT)
    knots = crossing_knots(m, level)
    assert knots.shape == (n, 4) and (np.diff(knots, axis=-1) >= 0.0).all()
    assert (knots[:, 0] == 0.0).all() and (knots[:, -1] == DT).all()
    found = 0
    for i in range(n):
        for t0, t1 in zip(knots[i, :-1], knots[i, 1:], strict=True):
            if t1 - t0 < 1e-9:
                continue
            tq = np.linspace(t0, t1, 51)[1:-1]
            y = y0[i] + vy[i] * tq + 0.5 * ay[i] * tq * tq - level
            assert (y > -1e-12).all() or (y < 1e-12).all(), (i, t0, t1)
        for t in knots[i, 1:-1]:
            if 0.0 < t < DT:
                assert abs(y0[i] + vy[i] * t + 0.5 * ay[i] * t * t - level) < 1e-12
                found += 1
    assert found > 50


def test_crossing_knots_of_a_multi_segment_motion():
    """Up through 1.0 on the first piece (0.97 + t = 1 at t = 0.03); on the second, from y = 1.02 at 0.05 with
    speed 1 and −60 m/s², back down where 30 t'² − t' − 0.02 = 0, t' = (1 + √3.4) / 60."""
    t = np.array([[0.0, 0.05, DT]])
    x, v = trajectory(0.97, 1.0, [0.0, 0.05], [0.0, -60.0], t[0], clamp=False)
    m = Motion.from_samples(t, x[None], v[None])
    knots = crossing_knots(m, 1.0)[0]
    assert np.isclose(knots, 0.03, rtol=0, atol=1e-12).sum() == 1
    assert np.isclose(knots, 0.05 + (1.0 + np.sqrt(3.4)) / 60.0, rtol=0, atol=1e-12).sum() == 1
    assert knots.shape == (7,)


def test_gap_extrema_broadcast_batches():
    """Motions with different batch shapes broadcast like arrays: ``(3, 1)`` behind ``(1, 4)`` gives ``(3, 4)``
    pairs, each equal to the dense sampling of its gap (and to the pair alone)."""
    rng = np.random.default_rng(12)
    behind = Motion.constant(rng.uniform(-10, 0, (3, 1)), rng.uniform(0, 30, (3, 1)), rng.uniform(-8, 2.5, (3, 1)), DT)
    ahead = Motion.constant(rng.uniform(0, 10, (1, 4)), rng.uniform(0, 30, (1, 4)), rng.uniform(-8, 2.5, (1, 4)), DT)
    lo, hi = gap_extrema(behind, ahead)
    assert lo.shape == hi.shape == (3, 4)
    for i in range(3):
        for j in range(4):
            d = ahead.at(TQ[None, None, :])[0][0, j] - behind.at(TQ[None, None, :])[0][i, 0]
            assert d.min() - 1e-4 <= lo[i, j] <= d.min() + 1e-12 and d.max() - 1e-12 <= hi[i, j] <= d.max() + 1e-4
            one = gap_extrema(Motion(*(getattr(behind, f)[i, 0] for f in ("t", "x", "v", "acc"))),
                              Motion(*(getattr(ahead, f)[0, j] for f in ("t", "x", "v", "acc"))))  # fmt: skip
            assert (one[0], one[1]) == pytest.approx((lo[i, j], hi[i, j]), abs=1e-12)


def test_extrema_match_dense_sampling_of_multi_segment_motions():
    rng = np.random.default_rng(9)
    n = 300
    t = np.concatenate([np.zeros((n, 1)), np.sort(rng.uniform(0, DT, (n, 3)), 1), np.full((n, 1), DT)], 1)
    t[:30, 2] = t[:30, 1]  # repeated knots
    accs = rng.uniform(-3.0, 3.0, (n, 4))
    y0, vy = rng.uniform(-1, 1, n), rng.uniform(-0.3, 0.3, n)
    lo, hi = np.empty(n), np.empty(n)
    dense = np.empty((n, TQ.size))
    ms = []
    for i in range(n):
        y, vv = trajectory(y0[i], vy[i], list(t[i, :-1]), list(accs[i]), t[i], clamp=False)
        ms.append((y, vv))
        dense[i] = trajectory(y0[i], vy[i], list(t[i, :-1]), list(accs[i]), TQ, clamp=False)[0]
    m = Motion.from_samples(t, np.stack([q[0] for q in ms]), np.stack([q[1] for q in ms]))
    lo, hi = extrema(m)
    assert (lo <= dense.min(1) + 1e-12).all() and (hi >= dense.max(1) - 1e-12).all()
    step = TQ[1] - TQ[0]
    np.testing.assert_allclose(lo, dense.min(1), rtol=0, atol=3.0 * step * step / 8 + 1e-12)
    np.testing.assert_allclose(hi, dense.max(1), rtol=0, atol=3.0 * step * step / 8 + 1e-12)
    # The gap of a motion to itself shifted by a constant is that constant, exactly at the extrema.
    shifted = Motion(t=m.t, x=m.x + 5.0, v=m.v, acc=m.acc)
    g_lo, g_hi = gap_extrema(m, shifted)
    np.testing.assert_allclose(g_lo, 5.0, atol=1e-12)
    np.testing.assert_allclose(g_hi, 5.0, atol=1e-12)
    # A window that always holds gives the unwindowed extrema; one that never does gives (inf, -inf).
    always = Motion.free(np.full(n, 10.0), np.zeros(n), np.zeros(n), DT)
    w_lo, w_hi = windowed_gap_extrema(m, shifted, always, crossing_knots(always, 0.0), 0.0)
    np.testing.assert_allclose(w_lo, 5.0, atol=1e-12)
    np.testing.assert_allclose(w_hi, 5.0, atol=1e-12)
    n_lo, n_hi = windowed_gap_extrema(m, shifted, always, crossing_knots(always, 20.0), 20.0)
    assert (n_lo == np.inf).all() and (n_hi == -np.inf).all()


def test_windowed_gap_extrema_broadcast_batches():
    """``(3, 1)`` behind ``(1, 4)`` with a ``(1, 1)`` lateral motion: ``(3, 4)`` pairs, each as the pair alone."""
    rng = np.random.default_rng(13)
    behind = Motion.constant(rng.uniform(-10, 0, (3, 1)), rng.uniform(0, 30, (3, 1)), rng.uniform(-8, 2.5, (3, 1)), DT)
    ahead = Motion.constant(rng.uniform(0, 10, (1, 4)), rng.uniform(0, 30, (1, 4)), rng.uniform(-8, 2.5, (1, 4)), DT)
    lat = Motion.free(np.full((1, 1), 0.98), np.full((1, 1), 0.5), np.zeros((1, 1)), DT)  # crosses 1.0 at 0.04 s
    lo, hi = windowed_gap_extrema(behind, ahead, lat, crossing_knots(lat, 1.0), 1.0)
    assert lo.shape == hi.shape == (3, 4)
    for i in range(3):
        for j in range(4):

            def pick(m, idx):
                return Motion(*(getattr(m, f)[idx] for f in ("t", "x", "v", "acc")))

            one_lat = pick(lat, (0, 0))
            one = windowed_gap_extrema(pick(behind, (i, 0)), pick(ahead, (0, j)), one_lat, crossing_knots(one_lat, 1.0),
                                       1.0)  # fmt: skip
            assert (one[0], one[1]) == pytest.approx((lo[i, j], hi[i, j]), abs=1e-12)
            tq = np.linspace(0.04, DT, 601)
            d = ahead.at(tq[None, None, :])[0][0, j] - behind.at(tq[None, None, :])[0][i, 0]
            assert d.min() - 1e-5 <= lo[i, j] <= d.min() + 1e-12


# --- Mutation review of the `sim` group (kinematics survivors): each test below states the behaviour it pins.


def _to_longdouble(q):
    """``q`` in extended precision with bits below float64's last one (so that rounding to float64 loses them)."""
    return np.asarray(q, np.longdouble) * (1 + np.longdouble(2.0) ** -60)


@pytest.mark.parametrize("make", [Motion.constant, Motion.free])
@pytest.mark.parametrize("convert", [np.float32, _to_longdouble, lambda q: np.asarray(q).round().astype(np.int64)])
@pytest.mark.parametrize("which", [0, 1, 2])
def test_motions_are_float64_whatever_the_real_dtype_of_an_input(make, convert, which):
    """``Motion.constant`` / ``Motion.free`` take each of ``x, v, a`` at its float64 value: an integer, float32 or
    extended-precision input gives float64 knots, bit-identical to those of the same inputs first converted to
    float64 (no part of the motion is computed in float32, in integers or in extended precision; ``dt`` is never
    truncated to an integer time)."""
    if convert is _to_longdouble and np.finfo(np.longdouble).nmant <= np.finfo(np.float64).nmant:
        pytest.skip("np.longdouble is float64 on this platform")
    args = [np.array([12.345678901234567, -3.75]), np.array([0.123456789, 20.5]), np.array([-3.3, 1.7])]
    args[which] = convert(args[which])
    m = make(*args, DT)
    ref = make(*(np.asarray(q, np.float64) for q in args), DT)
    for f in ("t", "x", "v", "acc"):
        got = getattr(m, f)
        assert got.dtype == np.float64, f
        np.testing.assert_array_equal(got, getattr(ref, f), err_msg=f)
    # The float64 motion itself, by hand: the end state at dt (free), the stop knot (constant, entry 0 brakes).
    x, v, a = (np.asarray(q, np.float64) for q in args)
    if make == Motion.free:
        np.testing.assert_array_equal(m.t, [[0.0, DT], [0.0, DT]])
        np.testing.assert_allclose(m.x[:, 1], x + v * DT + 0.5 * a * DT**2, rtol=1e-15, atol=1e-15)
    else:
        if which != 1:  # an integer speed 0 is at rest: no stop inside the period
            assert m.t[0, 1] == pytest.approx(v[0] / -a[0], rel=1e-15)
            assert m.x[0, 2] == pytest.approx(x[0] + v[0] ** 2 / (-2.0 * a[0]), rel=1e-15)


def test_from_samples_of_a_single_motion_and_of_a_two_by_two_batch():
    """The knots are on the last axis whatever the batch: one motion (1-D arrays) and a ``(2, 2)`` batch of motions
    each give the accelerations of their own samples."""
    t = np.array([0.0, 0.03, 0.07, DT])
    xk, vk = trajectory(2.0, 10.0, [0.0, 0.03, 0.07], [1.5, -4.0, 2.0], t)
    one = Motion.from_samples(t, xk, vk)
    assert one.acc.shape == (3,)
    np.testing.assert_allclose(one.acc, [1.5, -4.0, 2.0], rtol=0, atol=1e-9)
    accs = np.array([[[1.5, -4.0, 2.0], [0.0, 0.5, -1.0]], [[-2.0, 0.0, 3.0], [2.5, 2.5, -0.5]]])
    starts = [0.0, 0.03, 0.07]
    samples = [trajectory(5.0 * i, 12.0 + j, starts, list(accs[i, j]), t) for i in range(2) for j in range(2)]
    xs = np.stack([s[0] for s in samples]).reshape(2, 2, 4)
    vs = np.stack([s[1] for s in samples]).reshape(2, 2, 4)
    batch = Motion.from_samples(np.broadcast_to(t, (2, 2, 4)), xs, vs)
    assert batch.acc.shape == (2, 2, 3)
    np.testing.assert_allclose(batch.acc, accs, rtol=0, atol=1e-9)


def test_at_a_knot_is_that_knots_sample_exactly():
    """A knot is an exact sample of the motion: ``at`` a knot returns the stored ``(x, v)`` (the segment that starts
    there, not the previous one carried to its end). For a vehicle stopping inside the period that is speed exactly
    0 at its stop knot, where ``v + a · t_stop`` rounds to 6.9e-18."""
    v, a = 0.05991188490091204, -7.002845080054524
    m = Motion.constant(0.0, v, a, DT)
    assert v + a * m.t[1] != 0.0  # the previous segment carried to the stop knot is not exactly at rest
    xq, vq = m.at(m.t)
    assert vq[1] == 0.0 and xq[1] == pytest.approx(v * v / (-2.0 * a), rel=1e-12)
    np.testing.assert_array_equal(xq, m.x)
    np.testing.assert_array_equal(vq, m.v)
    # Every knot of switched fleets' motions (repeated knots included).
    fm = Fleet.switched(*_switched_draws(5, 100), DT).motion(...)
    xq, vq = fm.at(fm.t)
    np.testing.assert_array_equal(xq, fm.x)
    np.testing.assert_array_equal(vq, fm.v)


def test_a_vehicle_at_rest_that_brakes_stays_and_one_that_stops_ends_exactly_at_rest():
    """Entry 0 is at rest and brakes: it does not stop inside the period (``t_stop = dt``, acceleration 0, one
    segment: knots ``0, dt, dt``). Entry 1 stops at ``v / −a`` inside the period: its end speed is exactly 0 (not
    the 6.9e-18 that ``v + a · t_stop`` rounds to)."""
    v, a = 0.05991188490091204, -7.002845080054524
    f = Fleet.constant(np.array([5.0, 0.0]), np.array([0.0, v]), np.array([-4.0, a]), DT)
    assert f.acc[0] == 0.0 and f.t_stop[0] == DT and f.x_end[0] == 5.0 and f.v_end[0] == 0.0
    np.testing.assert_array_equal(f.motion(0).t, [0.0, DT, DT])
    assert f.t_stop[1] == pytest.approx(v / -a, rel=1e-15) and f.t_stop[1] < DT
    assert f.v_end[1] == 0.0
    assert f.x_end[1] == pytest.approx(v * v / (-2.0 * a), rel=1e-12)


def _driven_max(x, v, a1, t_sw, a2):
    """Per row, the largest |acceleration| each vehicle actually drives (reference integration): a1 unless at rest
    and not accelerating; after a switch, a2 unless at rest there and not accelerating."""
    draws = zip(x.ravel(), v.ravel(), a1.ravel(), t_sw.ravel(), strict=True)
    v_at_switch = np.array([trajectory(x0, v0, [0.0], [a], np.array([min(ts, DT)]))[1][0] for x0, v0, a, ts in draws])
    v_at_switch = v_at_switch.reshape(v.shape)
    acc_on = np.where((v > 0.0) | (a1 > 0.0), np.abs(a1), 0.0)
    acc_on = np.maximum(acc_on, np.where((t_sw < DT) & ((v_at_switch > 0.0) | (a2 > 0.0)), np.abs(a2), 0.0))
    return acc_on.max(1)


def test_gentle_accelerations_are_bounded_exactly_and_every_motion_segment_lies_within_the_bound():
    """With every |acceleration| below 1 m/s² the per-row bound is still exactly the largest one driven (no floor
    of 1, nothing counted for vehicles that do not switch), and it is the largest |acceleration| of the rows'
    motions in any segment (a vehicle that does not switch drives nothing on its unused segments)."""
    x, v, a1, t_sw, a2 = (q.reshape(6, 10) for q in _switched_draws(6, 60))
    a1, a2 = a1 / 10.0, a2 / 10.0
    assert np.abs(a1).max() < 1.0 and np.abs(a2).max() < 1.0
    assert (t_sw >= DT).any() and (t_sw < DT).any()  # vehicles with and without a switch
    fleet = Fleet.switched(x, v, a1, t_sw, a2, DT)
    row = fleet.row_max_abs_acc()
    np.testing.assert_array_equal(row, _driven_max(x, v, a1, t_sw, a2))
    assert (row < 1.0).all()
    m = fleet.motion(...)
    np.testing.assert_array_equal(np.abs(m.acc).max(-1).max(-1), row)


def test_row_bound_of_a_switching_fleet_without_columns_is_zero():
    """A fleet with a switch part, cut to no columns (``(B, 0)``): every row's bound is 0, like :attr:`max_abs_acc`'s
    (and like a fleet without switches, tested above)."""
    fleet = Fleet.switched(*(q.reshape(3, 4) for q in _switched_draws(7, 12)), DT)
    assert fleet.switch is not None
    fields = ("x", "v", "acc", "t_stop", "x_end", "v_end")
    cut = Fleet(
        *(getattr(fleet, f)[:, :0] for f in fields),
        dt=DT,
        switch=Switch(*(getattr(fleet.switch, f)[:, :0] for f in ("mask", "t", "x", "v", "acc", "t_stop"))),
    )
    np.testing.assert_array_equal(cut.row_max_abs_acc(), [0.0, 0.0, 0.0])
    assert cut.max_abs_acc == 0.0


# A gap by hand, with dt = 0.5 s so that every number is a binary fraction (exact): behind cruises at 10 m/s, ahead
# starts 1 m in front at 9.75 m/s and accelerates at 1 m/s². The gap is 1 − t/4 + t²/2 (relative acceleration exactly
# 1 m/s²): its minimum 1 − 1/32 = 0.96875 at t = 0.25, the vertex; 0.9765625 at t = 0.125; 1 at t = 0 and t = 0.5.
HAND_DT = 0.5
HAND_BEHIND = Motion.constant(0.0, 10.0, 0.0, HAND_DT)
HAND_AHEAD = Motion.free(1.0, 9.75, 1.0, HAND_DT)


def test_extrema_at_an_interior_vertex_by_hand():
    """Motions over 0.5 s: ``−t/4 + t²/2`` (a = 1, minimum −1/32 at 0.25), its mirror (maximum 1/32),
    ``−t/8 + t²/4`` (a = 1/2, minimum −1/64) and a constant 1; and the hand gap above (minimum 0.96875)."""
    m = Motion.free([0.0, 0.0, 0.0, 1.0], [-0.25, 0.25, -0.125, 0.0], [1.0, -1.0, 0.5, 0.0], HAND_DT)
    lo, hi = extrema(m)
    np.testing.assert_array_equal(lo, [-1.0 / 32.0, 0.0, -1.0 / 64.0, 1.0])
    np.testing.assert_array_equal(hi, [0.0, 1.0 / 32.0, 0.0, 1.0])
    assert gap_extrema(HAND_BEHIND, HAND_AHEAD) == (0.96875, 1.0)


def test_windowed_gap_extrema_by_hand_with_the_batch_from_the_lateral_motion():
    """The hand gap in four windows (level 0): ``y = 1/8 − t`` (above until 0.125: the gap falls from 1 to
    0.9765625), ``y = −1/8 + t`` (above from 0.125: the vertex 0.96875 and 1 at the end), always above (0.96875, 1),
    never (inf, −inf). One longitudinal pair and four lateral motions broadcast to four results; one lateral
    motion alone gives scalars."""
    zero = np.zeros(4)
    lat = Motion.free(np.array([0.125, -0.125, 1.0, -1.0]), np.array([-1.0, 1.0, 0.0, 0.0]), zero, HAND_DT)
    lo, hi = windowed_gap_extrema(HAND_BEHIND, HAND_AHEAD, lat, crossing_knots(lat, 0.0), 0.0)
    assert lo.shape == hi.shape == (4,)
    exp_lo, exp_hi = [0.9765625, 0.96875, 0.96875, np.inf], [1.0, 1.0, 1.0, -np.inf]
    np.testing.assert_array_equal(lo, exp_lo)
    np.testing.assert_array_equal(hi, exp_hi)
    for i in range(4):
        one = Motion(*(getattr(lat, f)[i] for f in ("t", "x", "v", "acc")))
        o_lo, o_hi = windowed_gap_extrema(HAND_BEHIND, HAND_AHEAD, one, crossing_knots(one, 0.0), 0.0)
        assert np.shape(o_lo) == np.shape(o_hi) == ()
        assert (o_lo, o_hi) == (exp_lo[i], exp_hi[i])


def test_a_window_that_holds_at_all_but_one_instant():
    """``y = (t − 1/4)²`` touches the level 0 at t = 0.25 (the period's middle) and is above it everywhere else:
    the window is the whole period but that instant, so the extrema are the whole period's, the vertex's 0.96875
    included as the infimum (the gap is continuous), and 1."""
    lat = Motion.free(0.0625, -0.5, 2.0, HAND_DT)
    tq = np.linspace(0.0, HAND_DT, 401)
    y = lat.at(tq)[0]
    assert y[200] == 0.0 and (np.delete(y, 200) > 0.0).all()  # tq[200] = 0.25
    lo, hi = windowed_gap_extrema(HAND_BEHIND, HAND_AHEAD, lat, crossing_knots(lat, 0.0), 0.0)
    assert (lo, hi) == (0.96875, 1.0)


@pytest.mark.parametrize("dt", [DT, 2.0])
def test_a_motion_that_never_reaches_the_level_gets_no_extra_knot(dt):
    """Rows that never reach level 0 (checked on a dense grid): at rest below it and above it, cruising away from
    it, and a parabola that turns back before reaching it (from 0.005 at −0.1 m/s with 1.5 m/s²: lowest 0.005 −
    0.01/3). ``crossing_knots`` adds no instant: every returned knot is 0 or ``dt`` (also over a 2 s period)."""
    m = Motion.free([-0.05, 1.0, 0.5, 0.005], [0.0, 0.0, 0.3, -0.1], [0.0, 0.0, 0.0, 1.5], dt)
    y = m.at(np.broadcast_to(np.linspace(0.0, dt, 2001), (4, 2001)))[0]
    assert ((y > 0.0).all(1) | (y < 0.0).all(1)).all()
    knots = crossing_knots(m, 0.0)
    assert knots.shape == (4, 4)
    assert ((knots == 0.0) | (knots == dt)).all(), knots
