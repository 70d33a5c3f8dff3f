"""``lane_checks`` at the edges of its shortcuts: the near-pair filter at its bound, the "at rest all period" skip,
pairs in the last columns, a fleet without pairs. Each expected outcome is derived by hand in the test's docstring
from constant-acceleration kinematics (``x(t) = x0 + v0 t + a t²/2`` until a stop)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.sim.checks import lane_checks
from safelane.sim.kinematics import Fleet

#: The checks and motions divide only where it is safe (or under errstate): no floating-point warning escapes.
pytestmark = pytest.mark.filterwarnings("error")

PARAMS = Params()
DT = PARAMS.dt
M = PARAMS.p_m


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
