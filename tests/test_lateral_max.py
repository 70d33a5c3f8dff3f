"""The conflict zone's test, ``shield.decide.lateral_max``: the exact maximum over ``[0, dt]`` of one free segment
``y0 + vy0 t + a t²/2``, against a dense sampling of the segment and a few hand-computed cases.

The reference samples the parabola itself (it imports nothing from the library but the function judged): the
sampled maximum is a lower bound of the exact one, and falls short of it by at most ``|a| h²/8`` on a grid of step
``h`` (the parabola's drop half a step away from its vertex).
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane.safety._backend import ARRAY, SCALAR
from safelane.shield.decide import lateral_max

#: Samples per period of the reference grid.
N_T = 4001


def _end(y0, vy0, a, dt):
    return y0 + vy0 * dt + 0.5 * a * dt * dt


def _sampled_max(y0, vy0, a, dt):
    t = np.linspace(0.0, dt, N_T)
    return (y0[:, None] + vy0[:, None] * t + 0.5 * a[:, None] * t * t).max(-1)


@pytest.mark.parametrize(
    ("y0", "vy0", "a", "dt", "expected"),
    [
        (0.0, 1.0, -10.0, 0.2, 0.05),  # vertex at t = 0.1, inside: above both ends (0 and 0)
        (0.0, 1.0, -10.0, 0.05, 0.0375),  # vertex at t = 0.1, after the period: the end, 0.05 - 0.0125
        (0.5, -1.0, -4.0, 0.5, 0.5),  # moving down and braking down: the start
        (0.5, -1.0, 4.0, 1.0, 1.5),  # a minimum inside (a > 0): the larger end, 0.5 - 1 + 2
        (0.25, 2.0, 0.0, 0.5, 1.25),  # no acceleration: the end
    ],
)
def test_hand_computed_cases(y0, vy0, a, dt, expected):
    got = lateral_max(ARRAY, np.array([y0]), np.array([vy0]), np.array([a]), np.array([_end(y0, vy0, a, dt)]), dt)
    assert got[0] == pytest.approx(expected, abs=1e-12)
    assert lateral_max(SCALAR, y0, vy0, a, _end(y0, vy0, a, dt), dt) == got[0]


def test_matches_the_sampled_maximum_on_random_segments():
    rng = np.random.default_rng(20261128)
    n = 3000
    y0 = rng.uniform(-2.0, 4.0, n)
    vy0 = rng.uniform(-3.0, 3.0, n)
    a = rng.uniform(-6.0, 6.0, n)
    a[::7] = 0.0  # no acceleration
    dt = 0.4
    got = lateral_max(ARRAY, y0, vy0, a, _end(y0, vy0, a, dt), dt)
    ref = _sampled_max(y0, vy0, a, dt)
    slack = np.abs(a) * (dt / (N_T - 1)) ** 2 / 8.0 + 1e-12
    assert np.all(got >= ref - 1e-12)
    assert np.all(got <= ref + slack)
    # The vertex matters: about one segment in twelve peaks strictly inside the period, above both its ends.
    inside = (a < 0.0) & (vy0 > 0.0) & (-vy0 / np.where(a < 0.0, a, -1.0) < dt)
    assert inside.sum() > n // 20
    ends = np.maximum(y0, _end(y0, vy0, a, dt))
    assert np.all(got[inside] > ends[inside])
    # The same function on floats gives the same bits.
    rows = range(0, n, 97)
    assert [lateral_max(SCALAR, y0[i], vy0[i], a[i], _end(y0[i], vy0[i], a[i], dt), dt) for i in rows] == list(
        got[list(rows)]
    )
