"""``lane_checks`` and ``ego_checks`` at the edges of their shortcuts. ``lane_checks``: the near-pair filter at and on
its bound, the "at rest all period" skip, per-pair rest, stop-and-go pairs, the exact edges of contact and of the
margin's tolerance, a fleet without pairs. ``ego_checks``: the near-pair filter at its bound, an ego exactly on a
lateral level (the windows are ``y > level``, strict), dips inside windows cut by crossings, a stop inside the period
with the ego settled. Each expected outcome is derived by hand in the test's docstring from constant-acceleration
kinematics (``x(t) = x0 + v0 t + a t²/2`` until a stop)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.sim.checks import ego_checks, lane_checks
from safelane.sim.kinematics import Fleet, Motion

#: The checks and motions divide only where it is safe (or under errstate): no floating-point warning escapes.
pytestmark = pytest.mark.filterwarnings("error")

PARAMS = Params()
DT = PARAMS.dt
M = PARAMS.p_m
CONFLICT = PARAMS.y_safe + 1e-9
OVERLAP = PARAMS.lane_width - PARAMS.vehicle_width


def _check(x, v, a, switch=None):
    x, v, a = (np.asfortranarray(np.atleast_2d(np.asarray(q, float))) for q in (x, v, a))
    fleet = Fleet.constant(x, v, a, DT) if switch is None else Fleet.switched(x, v, a, *switch, DT)
    b = SimpleNamespace(valid=np.ones(x.shape, bool), human=np.zeros(x.shape, bool))
    collided, violated, ratio = lane_checks(b, PARAMS, fleet)
    return bool(collided[0]), bool(violated[0]), float(ratio[0])


def test_a_pair_reaching_the_filters_bound_is_still_checked():
    """Behind accelerating at 2.5, ahead braking at 2.5 (a_max = 2.5), closing at 1 m/s: the gap falls by exactly
    the filter's bound, |Δv| dt + a_max dt² = 0.1 + 0.025 m, to its minimum at dt. Starting 0.125 m − 5e-7 m above
    the margin's edge, it ends 5e-7 m inside it: a violation the filter must not drop."""
    gap0 = M - 1e-9 + 0.125 - 5e-7
    collided, violated, ratio = _check([0.0, gap0], [20.0, 19.0], [2.5, -2.5])
    assert (collided, violated) == (False, True)
    assert ratio == pytest.approx((gap0 - 0.125) / M, abs=1e-12)


@pytest.mark.parametrize(
    ("v", "a", "moved"),
    [
        ((0.0, 0.0), (2.5, 0.0), 0.5 * 2.5 * DT**2),  # behind starts from rest: 0.0125 m
        ((0.5, 0.1), (-8.0, -8.0), 0.5**2 / 16 - 0.1**2 / 16),  # both brake to a stop inside the period
        ((1.0, 1.0), (-15.0, -30.0), 1.0 / 30.0 - 1.0 / 60.0),  # both from 1 m/s to a stop inside the period
    ],
)
def test_a_pair_not_at_rest_all_period_is_checked_exactly(v, a, moved):
    """Only a pair at rest all period keeps its gap. Here the gap shrinks by ``moved`` (the difference of the
    braking distances ``v²/2|a|``, or ``a dt²/2`` from rest) from 5 mm above the margin: a violation."""
    gap0 = M + 0.005
    assert moved > 0.006
    collided, violated, ratio = _check([0.0, gap0], v, a)
    assert (collided, violated) == (False, True)
    assert ratio == pytest.approx((gap0 - moved) / M, abs=1e-12)


def test_a_vehicle_that_starts_and_stops_inside_the_period_is_not_at_rest():
    """Behind: from rest, 2.5 m/s² until 0.05 s (0.125 m/s, 3.125 mm), then 8 m/s² to a stop 15.6 ms later
    (0.125² / 16 = 0.977 mm): at rest at both ends, 4.1 mm further. From 2 mm above the margin, the gap ends
    2.1 mm inside it."""
    gap0 = M + 0.002
    moved = 0.5 * 2.5 * 0.05**2 + 0.125**2 / 16.0
    switch = (np.array([[0.05, 1.0]]), np.array([[-8.0, 0.0]]))
    collided, violated, ratio = _check([0.0, gap0], [0.0, 0.0], [2.5, 0.0], switch)
    assert (collided, violated) == (False, True)
    assert ratio == pytest.approx((gap0 - moved) / M, abs=1e-12)


def test_each_pair_is_at_rest_by_its_own_vehicles():
    """F at rest, L1 coasting at 2 m/s towards L2 at rest 1 cm beyond the margin: the pair (L1, L2) closes by 0.2 m
    (violated) though F and L2 are at rest."""
    collided, violated, ratio = _check([0.0, 30.0, 30.0 + M + 0.01], [0.0, 2.0, 0.0], [0.0, 0.0, 0.0])
    assert (collided, violated) == (False, True)
    assert ratio == pytest.approx((M + 0.01 - 0.2) / M, abs=1e-12)


def test_pairs_at_rest_at_and_just_above_the_margin():
    """At rest all period: the gap is constant; exactly the margin is no violation (``gap < margin − 1 nm``)."""
    assert _check([0.0, M], [0.0, 0.0], [-8.0, 0.0]) == (False, False, 1.0)
    # The edges themselves: 1 nm inside the margin is its tolerance (not a violation), touching is no overlap.
    assert _check([0.0, M - 1e-9], [0.0, 0.0], [0.0, 0.0])[:2] == (False, False)
    assert _check([0.0, M - 2e-9], [0.0, 0.0], [0.0, 0.0])[:2] == (False, True)
    length = PARAMS.vehicle_length
    assert _check([0.0, length], [0.0, 0.0], [0.0, 0.0])[:2] == (False, True)
    assert _check([0.0, np.nextafter(length, 0.0)], [0.0, 0.0], [0.0, 0.0])[:2] == (True, True)
    assert _check([0.0, M + 0.03, 100.0], [0.0, 0.0, 20.0], [0.0, 0.0, -8.0])[2] == pytest.approx((M + 0.03) / M)


def test_a_fleet_without_pairs():
    """One vehicle per scenario: no pair, nothing violated, the ratio is inf."""
    assert _check([0.0], [10.0], [0.0]) == (False, False, np.inf)


def test_stop_and_go_pair_minimum():
    """Behind at 0.32 m/s braking at 8 stops at 0.04 s; ahead starts from rest at 2.5 m/s². Until 0.04 s the gap is
    7.05 − 0.32 t + 5.25 t² (minimum 7.05 − 0.32² / 21 at t = 0.32 / 10.5 = 0.0305 s), then it only grows: the
    exact minimum is 7.05 − 0.1024 / 21, no violation."""
    collided, violated, ratio = _check([0.0, 7.05], [0.32, 0.0], [-8.0, 2.5])
    assert (collided, violated) == (False, False)
    assert ratio * M == pytest.approx(7.05 - 0.1024 / 21.0, abs=1e-12)
    # The same with the roles' order of stopping reversed: ahead at 0.1 m/s stops at 0.0125 s, behind from rest.
    collided, violated, ratio = _check([0.0, 7.05], [0.0, 0.1], [2.5, -8.0])
    # gap = 7.05 + 0.1 t − 5.25 t² until 0.0125 s, then 7.05 + 0.000625 − 1.25 t² (behind): minimum at dt.
    assert ratio * M == pytest.approx(7.05 + 0.1**2 / 16.0 - 1.25 * DT**2, abs=1e-12)


def test_a_pair_exactly_on_the_filters_bound_is_sampled():
    """Behind braking at 8 (the row's a_max) at 10 m/s, ahead accelerating at 2.5 at 9.5 m/s: the gap can fall at
    most |Δv| dt + a_max dt² = 0.05 + 0.08 m. Starting exactly that (plus the filter's 1e-6 m) above the margin, it
    cannot come within it: the pair is not near and its ratio is the end samples' (the start, 7.130001 m), though
    the gap dips by 0.5² / (2 · 10.5) m mid-period (at 0.048 s)."""
    gap0 = 7.130001
    assert gap0 - abs(9.5 - 10.0) * DT == M + (8.0 * DT * DT + 1e-6)  # on the bound, in floating point too
    collided, violated, ratio = _check([0.0, gap0], [10.0, 9.5], [-8.0, 2.5])
    assert (collided, violated) == (False, False)
    assert ratio == gap0 / M
    # 1 ulp closer it is near, and its exact minimum is reported.
    closer = np.nextafter(gap0, 0.0)
    assert _check([0.0, closer], [10.0, 9.5], [-8.0, 2.5])[2] == pytest.approx((closer - 0.25 / 21.0) / M, abs=1e-12)


def test_a_pair_both_starting_and_stopping_inside_the_period_is_checked():
    """Both from rest, then braking at 8 from 0.05 s: behind at 2.5 m/s² first moves 0.5·2.5·0.05² + 0.125²/16 =
    4.102 mm, ahead at 1 m/s² 0.5·1·0.05² + 0.05²/16 = 1.406 mm: from 2 mm above the margin the gap ends 0.7 mm
    inside it, though both are at rest at both ends."""
    gap0 = M + 0.002
    moved = (0.5 * 2.5 * 0.05**2 + 0.125**2 / 16.0) - (0.5 * 1.0 * 0.05**2 + 0.05**2 / 16.0)
    switch = (np.array([[0.05, 0.05]]), np.array([[-8.0, -8.0]]))
    collided, violated, ratio = _check([0.0, gap0], [0.0, 0.0], [2.5, 1.0], switch)
    assert (collided, violated) == (False, True)
    assert ratio == pytest.approx((gap0 - moved) / M, abs=1e-12)


# --- ego_checks ------------------------------------------------------------------------------------------------


def _run(ego_x, ego_v, ego_a, ego_y, others_x, others_v, others_a, vy=0.0, ay=0.0):
    lon = Motion.constant(np.array([ego_x]), np.array([ego_v]), np.array([ego_a]), DT)
    lat = Motion.free(np.array([ego_y]), np.array([vy]), np.array([ay]), DT)
    x = np.asfortranarray([others_x], float)
    v = np.asfortranarray([others_v], float)
    others = Fleet.constant(x, v, np.asfortranarray([others_a], float), DT)
    b = SimpleNamespace(valid=np.ones(x.shape, bool))
    s = SimpleNamespace(x=x, v=v, ego=(np.array([ego_x]), np.array([ego_y]), np.array([ego_v]), np.array([vy])),
                        min_gap_f=np.full(1, np.inf), min_gap_l1=np.full(1, np.inf))  # fmt: skip
    collided, violated, gap_f, gap_l1 = ego_checks(b, PARAMS, s, lon, lat, others, CONFLICT, OVERLAP)
    return bool(collided[0]), bool(violated[0]), float(gap_f[0]), float(gap_l1[0])


def test_a_follower_closing_at_the_filters_bound_is_still_checked():
    """The ego brakes at a_x_d = 8, F (1 m/s faster) accelerates at 2.5, the row's largest |acceleration|: the gap
    ego − F shrinks by exactly the filter's bound, |Δv| dt + (8 + 2.5) dt²/2 = 0.1525 m, to its minimum at dt. From
    0.1525 m − 5e-7 m above the margin's edge it ends 5e-7 m inside: a violation the filter must not drop."""
    gap0 = PARAMS.p_m - 1e-9 + 0.1525 - 5e-7
    collided, violated, gap_f, gap_l1 = _run(0.0, 20.0, -8.0, 3.5, [-gap0, 60.0], [21.0, 20.0], [2.5, 0.0])
    assert (collided, violated) == (False, True)
    assert gap_f == pytest.approx(gap0 - 0.1525, abs=1e-12)
    # L1 stayed far: its gap is sampled at the period's ends, 60 m and 60 m + what the braking ego lost: 0.04 m.
    assert gap_l1 == 60.0


@pytest.mark.parametrize(
    ("ego_y", "expect"),
    [
        (OVERLAP + 1e-6, (True, True)),  # beyond both levels: contact and violation count
        (OVERLAP, (False, True)),  # exactly on the overlap level: beyond the conflict level only
        (CONFLICT, (False, False)),  # exactly on the conflict level: nothing counts
    ],
)
@pytest.mark.parametrize("l1_v", [30.0, 0.3])  # L1 cruising, or stopping inside the period (the stop knots' path)
def test_an_ego_exactly_on_a_level_is_not_beyond_it(ego_y, expect, l1_v):
    """The ego holds its lateral position; L1 is 3 m ahead (overlapping footprints, inside p_m) all period."""
    collided, violated, _, gap_l1 = _run(
        0.0, l1_v, 0.0, ego_y, [-40.0, 3.0], [l1_v, l1_v], [0.0, -8.0 if l1_v < 1 else 0.0]
    )
    assert (collided, violated) == expect
    if expect[1]:
        assert gap_l1 <= 3.0
    else:
        assert gap_l1 == np.inf


def test_a_stop_inside_the_period_with_the_ego_settled_in_the_target_lane():
    """Ego at 1 m/s braking at 8: stops after 0.125 s > dt, covering 0.1 − 0.04 = 0.06 m. L1 at 0.4 m/s braking at 8
    stops after 0.05 s, covering 0.01 m, from 7.04 m ahead: the gap falls from 7.04 to 7.04 + 0.01 − 0.06 = 6.99 m,
    monotonically (the ego is always the faster), so its minimum 6.99 m < p_m = 7 is a violation, not a contact."""
    collided, violated, _, gap_l1 = _run(0.0, 1.0, -8.0, 3.5, [-40.0, 7.04], [0.0, 0.4], [0.0, -8.0])
    assert (collided, violated) == (False, True)
    assert gap_l1 == pytest.approx(6.99, abs=1e-12)
    collided, violated, _, gap_l1 = _run(0.0, 1.0, -8.0, 3.5, [-40.0, 7.06], [0.0, 0.4], [0.0, -8.0])
    assert (collided, violated) == (False, False)
    assert gap_l1 == pytest.approx(7.01, abs=1e-12)


def test_a_dip_inside_a_window_cut_by_a_crossing():
    """The ego crosses the conflict level at 0.03 s (y = 0.82 + t); L1's gap, d0 − 0.48 t + 4 t² (ego braking at
    8 from 20 m/s, L1 cruising at 19.52), has its minimum d0 − 0.48² / 16 = d0 − 0.0144 at 0.06 s, inside the window
    [0.03, 0.1], below both of its ends (d0 − 0.0108, d0 − 0.008). From d0 = 7.012: 6.9976 < p_m, a violation only
    the vertex shows."""
    y0 = CONFLICT - 0.03
    _, violated, _, gap_l1 = _run(0.0, 20.0, -8.0, y0, [-40.0, 7.012], [20.0, 19.52], [0.0, 0.0], vy=1.0)
    assert violated
    assert gap_l1 == pytest.approx(7.012 - 0.0144, abs=1e-9)
    # F behind: the ego accelerates at 2.5, F (0.3 m/s faster) brakes at 2.5: ego − F = 7.005 − 0.3 t + 2.5 t², its
    # minimum 7.005 − 0.009 at 0.06 s inside the window; the window's ends give 6.99825 and 7.0.
    _, violated, gap_f, _ = _run(0.0, 20.0, 2.5, y0, [-7.005, 60.0], [20.3, 20.0], [-2.5, 0.0], vy=1.0)
    assert violated
    assert gap_f == pytest.approx(7.005 - 0.009, abs=1e-9)
    # Relative acceleration exactly 1 (the ego braking at 1, L1 cruising 0.06 m/s slower): 7.0015 − 0.06 t + t²/2,
    # minimum 7.0015 − 0.0018 = 6.9997 at 0.06 s; the window's ends give 7.00015 and 7.0005.
    _, violated, _, gap_l1 = _run(0.0, 20.0, -1.0, y0, [-40.0, 7.0015], [20.0, 19.94], [0.0, 0.0], vy=1.0)
    assert violated
    assert gap_l1 == pytest.approx(6.9997, abs=1e-9)


def test_a_window_between_two_crossings():
    """The ego's lateral position rises over the conflict level at 0.02 s and falls back at 0.09 s:
    y − level = −0.75 (t − 0.02)(t − 0.09), at most 0.75 · 0.035² = 0.92 mm above it. L1 6.9 m ahead at the ego's
    speed: inside p_m during [0.02, 0.09] only, a violation; 1 mm lower the ego never crosses and nothing counts."""
    y0, vy, ay = CONFLICT - 0.75 * 0.02 * 0.09, 0.75 * 0.11, -1.5
    collided, violated, _, gap_l1 = _run(0.0, 20.0, 0.0, y0, [-40.0, 6.9], [20.0, 20.0], [0.0, 0.0], vy, ay)
    assert (collided, violated) == (False, True)
    assert gap_l1 == pytest.approx(6.9, abs=1e-12)
    collided, violated, _, gap_l1 = _run(0.0, 20.0, 0.0, y0 - 0.001, [-40.0, 6.9], [20.0, 20.0], [0.0, 0.0], vy, ay)
    assert (collided, violated, gap_l1) == (False, False, np.inf)


def test_a_peak_before_the_window_does_not_count():
    """F (0.1 m/s faster, braking at 2.5) behind the ego (accelerating at 2.5): ego − F = 7.005 − 0.1 t + 2.5 t², its
    closest approach 7.004 at 0.02 s, before the ego crosses the conflict level at 0.03 s. Inside the window
    [0.03, 0.1] the closest is at its start: 7.005 − 0.003 + 0.00225 = 7.00425 m, no violation."""
    y0 = CONFLICT - 0.03
    _, violated, gap_f, _ = _run(0.0, 20.0, 2.5, y0, [-7.005, 60.0], [20.1, 20.0], [-2.5, 0.0], vy=1.0)
    assert not violated
    assert gap_f == pytest.approx(7.00425, abs=1e-9)


def test_an_ego_leaving_the_conflict_zone_counts_only_before_it_leaves():
    """L1 7.01 m ahead, the ego 0.2 m/s faster: 7.01 − 0.2 t, below p_m from 0.05 s on. Leaving the zone at 0.03 s
    (y = level + 0.03 − t) or at √(0.005 / 0.75) = 0.0816 s (y = level + 0.005 − 0.75 t², from 7.0175 m: 7.00118 m
    then), the ego was never in the zone while closer than p_m; far to the right of its own lane (y = −1) it never
    enters it."""
    for y0, vy, ay, d0 in ((CONFLICT + 0.03, -1.0, 0.0, 7.01), (CONFLICT + 0.005, 0.0, -1.5, 7.0175)):
        collided, violated, _, gap_l1 = _run(0.0, 20.0, 0.0, y0, [-40.0, d0], [20.0, 19.8], [0.0, 0.0], vy, ay)
        assert (collided, violated) == (False, False)
        assert gap_l1 >= PARAMS.p_m
    assert _run(0.0, 20.0, 0.0, -1.0, [-40.0, 3.0], [20.0, 20.0], [0.0, 0.0]) == (False, False, np.inf, np.inf)


def test_a_leader_exactly_on_the_filters_bound_is_sampled():
    """The ego cruising at 20 m/s, L1 at 19.9 accelerating at 2.5 (the row's largest): the gap can fall at most
    |Δv| dt + (8 + 2.5) dt²/2 = 0.01 + 0.0525 m. Starting exactly that (plus the filter's 1e-6 m) above p_m, L1 is
    not near: its gap is the end samples' (7.062501 m at the start, 7.065001 at the end), though the gap
    7.062501 − 0.1 t + 1.25 t² dips to 7.060501 at 0.04 s. One ulp closer the exact minimum is reported."""
    d0 = 7.062501
    reach = abs(19.9 - 20.0) * DT
    assert d0 - reach == PARAMS.p_m + 0.5 * (8.0 + 2.5) * DT * DT + 1e-6  # on the bound, in floating point too
    _, violated, _, gap_l1 = _run(0.0, 20.0, 0.0, 3.5, [-40.0, d0], [20.0, 19.9], [0.0, 2.5])
    assert not violated and gap_l1 == d0
    closer = np.nextafter(d0, 0.0)
    _, violated, _, gap_l1 = _run(0.0, 20.0, 0.0, 3.5, [-40.0, closer], [20.0, 19.9], [0.0, 2.5])
    assert not violated and gap_l1 == pytest.approx(closer - 0.002, abs=1e-9)


@pytest.mark.parametrize(
    ("y0", "vy", "ay", "d0"),
    [
        (OVERLAP - 0.05, 1.0, 0.0, 4.795),  # rising through the overlap level at 0.05 s
        (OVERLAP + 0.05, -1.0, 0.0, 4.805),  # falling through it at 0.05 s
        (OVERLAP + 0.005, -0.15, 1.5, 4.805),  # dipping below it at 0.0423 s (slowing to 0 at dt)
        (OVERLAP + 0.002, 0.05, -1.5, 4.8095),  # curving below it at 0.0948 s
    ],
)
def test_contact_only_outside_the_overlap_window_with_a_stop_inside_the_period(y0, vy, ay, d0):
    """L1 (0.4 m/s, braking at 8) stops at 0.05 s after 0.01 m, so the pair takes the stop-knot path. Rising case:
    the ego at rest, the gap d0 + 0.4 t − 4 t² is below the length 4.8 only until 0.0127 s, before the ego overlaps
    (from 0.05 s). Other cases: the ego at 0.2 m/s, the gap d0 + 0.2 t − 4 t² then d0 + 0.01 − 0.2 t after 0.05 s,
    below 4.8 only after the ego has left the overlap zone (at 0.075 s, resp. 0.0475 s and 0.09475 s). The ego is
    beyond the conflict level all period, inside p_m: a violation, never a contact."""
    ego_v = 0.0 if vy > 0 and ay == 0 else 0.2
    collided, violated, _, _ = _run(0.0, ego_v, 0.0, y0, [-40.0, d0], [0.0, 0.4], [0.0, -8.0], vy, ay)
    assert (collided, violated) == (False, True)


def test_touching_is_no_contact():
    """The ego and L1 at the same speed exactly a car's length apart, the ego in the target lane: touching, no
    overlap; a hair closer is a contact."""
    length = PARAMS.vehicle_length
    assert _run(0.0, 20.0, 0.0, 3.5, [-40.0, length], [20.0, 20.0], [0.0, 0.0])[:2] == (False, True)
    closer = np.nextafter(length, 0.0)
    assert _run(0.0, 20.0, 0.0, 3.5, [-40.0, closer], [20.0, 20.0], [0.0, 0.0])[:2] == (True, True)


def test_the_egos_contact_and_margin_edges_ahead_and_behind():
    """Constant gaps (everyone at 20 m/s), the ego in the target lane: a car's length exactly is touching (no
    contact), ``p_m − 1 nm`` exactly is the margin's tolerance (no violation), behind as ahead."""
    length, edge = PARAMS.vehicle_length, PARAMS.p_m - 1e-9
    far = 60.0
    assert _run(0.0, 20.0, 0.0, 3.5, [-length, far], [20.0, 20.0], [0.0, 0.0])[:2] == (False, True)
    assert _run(0.0, 20.0, 0.0, 3.5, [-edge, far], [20.0, 20.0], [0.0, 0.0])[:2] == (False, False)
    assert _run(0.0, 20.0, 0.0, 3.5, [-far, edge], [20.0, 20.0], [0.0, 0.0])[:2] == (False, False)
    assert _run(0.0, 20.0, 0.0, 3.5, [-far, edge - 1e-9], [20.0, 20.0], [0.0, 0.0])[:2] == (False, True)


def test_a_dip_with_relative_acceleration_one_over_the_whole_period():
    """The ego settled in the target lane braking at 1, L1 cruising 0.06 m/s slower: 7.0015 − 0.06 t + t²/2, its
    minimum 6.9997 at 0.06 s (ends 7.0015 and 7.0005); between target-lane vehicles the same relative motion."""
    _, violated, _, gap_l1 = _run(0.0, 20.0, -1.0, 3.5, [-40.0, 7.0015], [20.0, 19.94], [0.0, 0.0])
    assert violated and gap_l1 == pytest.approx(6.9997, abs=1e-9)
    collided, violated, ratio = _check([0.0, 7.0015], [20.0, 19.94], [-1.0, 0.0])
    assert (collided, violated) == (False, True) and ratio * M == pytest.approx(6.9997, abs=1e-9)
