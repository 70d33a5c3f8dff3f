"""The aggressiveness assessment (``shield/assessment.py``) against an independent reference.

The reference is the module docstring's rule written out in plain Python: the slope is NumPy's least-squares line
fit (``np.polyfit``) of the last ``window`` observed speeds against their observation times; aggressive evidence
(slope ``>= +threshold``, with a full window) latches "aggressive"; collaborative evidence (slope ``<= -threshold``)
switches to "collaborative" unless latched; the belief is kept otherwise; the first collaborative time is recorded.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane.shield import assessment as assess


def _reference(speeds, window, dt, threshold, t0=0.0):
    """Per row: ``(aggressive, latched, first_collaborative_s)`` after feeding ``speeds[k]`` at ``t0 + k dt``."""
    out = []
    for row in speeds:
        aggressive, latched, first = True, False, np.nan
        for k in range(len(row)):
            if k + 1 >= window:
                last = row[k + 1 - window : k + 1]
                slope = np.polyfit(np.arange(window) * dt, last, 1)[0]
                latched = latched or slope >= threshold
                if slope <= -threshold:
                    aggressive = False
            aggressive = aggressive or latched
            if np.isnan(first) and not aggressive:
                first = t0 + k * dt
        out.append((aggressive, latched, first))
    return out


def _feed(speeds, window, dt, threshold, t0=0.0):
    state = assess.AssessmentState.start(speeds.shape[0], window)
    for k in range(speeds.shape[1]):
        state = assess.update(state, speeds[:, k], t0 + k * dt, dt, threshold)
    return state


@pytest.mark.parametrize(("window", "dt", "threshold"), [(2, 0.1, 0.2), (3, 0.25, 0.5), (5, 0.1, 0.2), (8, 0.05, 1.0)])
def test_belief_matches_the_least_squares_reference(window, dt, threshold):
    """Random speed traces whose slopes straddle both thresholds (well away from them: round-off is not the
    question here), fed period by period, compared after every period."""
    rng = np.random.default_rng(window)
    b, steps = 60, 3 * window + 4
    # Per row: one acceleration throughout, or a switch to another one halfway (yield then push, etc.).
    levels = np.array([-3.0, -1.5, -0.5, 0.0, 0.5, 1.5, 3.0]) * threshold
    first, second = rng.choice(levels, b), rng.choice(levels, b)
    switch = rng.integers(window, steps, b)
    accel = np.where(np.arange(steps)[None, :] < switch[:, None], first[:, None], second[:, None])
    speeds = 30.0 + np.cumsum(accel, 1) * dt + rng.normal(0.0, 0.02 * threshold * dt, (b, steps))
    state = assess.AssessmentState.start(b, window)
    for k in range(steps):
        state = assess.update(state, speeds[:, k], 1.0 + k * dt, dt, threshold)
        assert (state.count == k + 1).all()
        ref = _reference(speeds[:, : k + 1], window, dt, threshold, t0=1.0)
        np.testing.assert_array_equal(state.aggressive, [r[0] for r in ref])
        np.testing.assert_array_equal(state.latched, [r[1] for r in ref])
        np.testing.assert_allclose(state.first_collaborative_s, [r[2] for r in ref], rtol=0, atol=1e-12)
        np.testing.assert_allclose(state.history[:, -min(k + 1, window) :], speeds[:, max(k + 1 - window, 0) : k + 1])
    assert not state.aggressive.all() and state.latched.any() and (state.aggressive & ~state.latched).any()


def test_slope_is_the_least_squares_slope_of_the_window():
    """A noisy line and an arbitrary trace: the belief flips exactly where the fitted slope crosses the threshold
    (slopes 1 % either side of it)."""
    dt, window = 0.1, 6
    times = np.arange(window) * dt
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 0.05, window)
    noise -= np.polyfit(times, noise, 1)[0] * times  # zero least-squares slope, not zero at every point
    for sign in (1.0, -1.0):
        for factor, flips in ((1.01, True), (0.99, False)):
            speeds = 25.0 + sign * factor * 0.3 * times + noise
            state = _feed(speeds[None, :], window, dt, 0.3)
            if sign > 0:
                assert state.latched[0] == flips and state.aggressive[0]
            else:
                assert state.aggressive[0] != flips and not state.latched[0]


def test_a_slope_exactly_at_the_threshold_counts_as_evidence():
    """dt = 0.5 and slope 0.25 are exact in binary: the fitted slope equals the threshold bit for bit."""
    dt, window, thr = 0.5, 5, 0.25
    t = np.arange(window) * dt
    up = _feed((10.0 + thr * t)[None, :], window, dt, thr)
    assert up.latched[0] and up.aggressive[0]
    down = _feed((10.0 - thr * t)[None, :], window, dt, thr)
    assert not down.aggressive[0] and not down.latched[0] and down.first_collaborative_s[0] == (window - 1) * dt


def test_start_state():
    s = assess.AssessmentState.start(3, 4)
    assert s.history.shape == (3, 4)
    assert s.count.shape == (3,) and s.count.dtype.kind == "i" and (s.count == 0).all()
    assert s.aggressive.dtype == bool and s.aggressive.all()
    assert s.latched.dtype == bool and not s.latched.any()
    assert np.isnan(s.first_collaborative_s).all() and s.first_collaborative_s.shape == (3,)


def test_nothing_is_decided_before_the_window_is_full_whatever_the_start_history():
    """Slopes far beyond the threshold, one observation short of a full window: no evidence either way."""
    dt, window = 0.1, 4
    for slope in (-10.0, 10.0):
        speeds = (20.0 + slope * np.arange(window - 1) * dt)[None, :]
        state = _feed(speeds, window, dt, 0.2)
        assert state.aggressive[0] and not state.latched[0] and np.isnan(state.first_collaborative_s[0])
        state = assess.update(state, np.array([20.0 + slope * (window - 1) * dt]), 1.0, dt, 0.2)
        assert state.latched[0] == (slope > 0) and state.aggressive[0] == (slope > 0)


def test_first_collaborative_time_is_kept_once_set():
    dt, window = 0.1, 3
    speeds = (30.0 - 1.0 * np.arange(12) * dt)[None, :]
    state = _feed(speeds, window, dt, 0.2, t0=2.0)
    assert state.first_collaborative_s[0] == pytest.approx(2.0 + (window - 1) * dt)
    assert not state.aggressive[0]
    flat = assess.update(state, np.array([speeds[0, -1]] * 1), 9.0, dt, 0.2)  # a cruise period: belief kept
    assert not flat.aggressive[0] and flat.first_collaborative_s[0] == state.first_collaborative_s[0]


def test_the_slope_is_summed_left_to_right_whatever_the_layout_of_the_history():
    """The slope's dot products in a fixed order (``assessment._dot``): the same bits as plain Python's left-to-right
    sum, for a C- and an F-ordered history alike (a BLAS product rounds differently by layout, build and CPU, which
    made the belief at its threshold machine-dependent; the compiled loop sums in this order too)."""
    rng = np.random.default_rng(5)
    history = rng.uniform(0.0, 40.0, (500, 5))
    times = (np.arange(5) - 2.0) * 0.1
    expected = []
    for row in history:
        total = row[0] * times[0]
        for h, w in zip(row[1:], times[1:], strict=True):
            total = total + h * w
        expected.append(total)
    for layout in (np.ascontiguousarray(history), np.asfortranarray(history)):
        assert np.array_equal(assess._dot(layout, times), np.array(expected))
    state = dataclasses.replace(assess.AssessmentState.start(500, 5), count=np.full(500, 9))  # a full window
    c_order = assess.update(dataclasses.replace(state, history=np.ascontiguousarray(history)), history[:, 0], 1.0,
                            0.1, 0.2)  # fmt: skip
    f_order = assess.update(dataclasses.replace(state, history=np.asfortranarray(history)), history[:, 0], 1.0, 0.1,
                            0.2)  # fmt: skip
    assert all(np.array_equal(getattr(c_order, f), getattr(f_order, f), equal_nan=f.endswith("_s"))
               for f in ("aggressive", "latched", "first_collaborative_s"))  # fmt: skip
    assert c_order.latched.any() and not c_order.aggressive.all()  # both kinds of evidence occur
