"""The shield's policy registry (``shield/policies.py``) as units: the variants' information flags, the registered
assessments (``observed``, ``truth``, ``slow``), the completion rules and the registry check.

The ``slow`` assessment is compared with its definition (the module docstring): the ``observed`` belief, with each
collaborative verdict released only ``assess_delay_s · (0.5 + u₁)`` after it was reached and never where
``u₂ < assess_miss``, ``u₁, u₂`` drawn per scenario from F's first observed state by the splitmix64 finaliser
(written out below from its published definition, Steele, Lea & Flood 2014 / Vigna's ``splitmix64.c``).
"""

from __future__ import annotations

import struct
from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.planners.variants import VARIANT_NAMES, VARIANTS
from safelane.shield import ShieldConfig, policies
from safelane.shield import assessment as assess
from safelane.shield.decide import commit_guard

MASK = (1 << 64) - 1


def _bits(x: float) -> int:
    return struct.unpack("<Q", struct.pack("<d", float(x)))[0]


def _ref_uniform(x0: float, v0: float, salt: int) -> float:
    """splitmix64's finaliser in Python integers (mod 2⁶⁴) over the key ``bits(x0)·φ ⊕ (bits(v0) + salt)``; the top
    53 bits as a fraction of 2⁵³."""
    h = (_bits(x0) * 0x9E3779B97F4A7C15) & MASK
    h ^= (_bits(v0) + salt) & MASK
    h = ((h ^ (h >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    h = ((h ^ (h >> 27)) * 0x94D049BB133111EB) & MASK
    h ^= h >> 31
    return (h >> 11) / 2.0**53


def test_scenario_uniform_is_splitmix64_of_the_first_state():
    rng = np.random.default_rng(5)
    x0 = np.concatenate([[0.0, -0.0, 1.0, -20.0, 1e-300], rng.uniform(-60.0, -5.0, 300)])
    v0 = np.concatenate([[0.0, 0.0, 30.0, 25.5, 0.0], rng.uniform(0.0, 40.0, 300)])
    for salt in (1, 2, 7):
        got = policies._scenario_uniform(x0, v0, salt)
        assert got.dtype == np.float64 and got.shape == x0.shape
        np.testing.assert_array_equal(got, [_ref_uniform(x, v, salt) for x, v in zip(x0, v0, strict=True)])
        assert ((got >= 0.0) & (got < 1.0)).all()
    many = policies._scenario_uniform(rng.uniform(-60, -5, 4000), rng.uniform(0, 40, 4000), 1)
    assert abs(many.mean() - 0.5) < 0.02 and abs((many < 0.25).mean() - 0.25) < 0.03  # uniform on [0, 1)
    # A row's draw does not depend on the batch it sits in.
    assert policies._scenario_uniform(x0[7:8], v0[7:8], 1)[0] == policies._scenario_uniform(x0, v0, 1)[7]


def _situation(t, f_x, ego_x, speed, truth=None):
    return SimpleNamespace(t=t, f_x=f_x, ego_x=ego_x, observed_f_speed=speed, f_aggressive_truth=truth)


def test_observed_assessment_is_the_assessment_module_with_the_configs_window_and_threshold():
    cfg = ShieldConfig(assess_window=3, assess_threshold=0.7)
    obs = policies.ASSESSMENTS["observed"]
    state = obs.start(4, cfg)
    assert state.history.shape == (4, 3)
    ref = assess.AssessmentState.start(4, 3)
    slopes = np.array([-0.8, -0.6, 0.6, 0.8])  # either side of ±0.7
    for k in range(5):
        speeds = 30.0 + slopes * k * 0.1
        state = obs.update(state, _situation(0.5 + 0.1 * k, None, None, speeds), 0.1, cfg)
        ref = assess.update(ref, speeds, 0.5 + 0.1 * k, 0.1, 0.7)
        for field in ("history", "count", "aggressive", "latched", "first_collaborative_s"):
            np.testing.assert_array_equal(getattr(state, field), getattr(ref, field))
    np.testing.assert_array_equal(obs.aggressive(state, None), [False, True, True, True])
    np.testing.assert_array_equal(state.latched, [False, False, False, True])
    assert state.first_collaborative_s[0] == pytest.approx(0.7)


def test_truth_assessment_reads_the_situations_truth_and_needs_it():
    truth = policies.ASSESSMENTS["truth"]
    cfg = ShieldConfig(assessment="truth")
    state = truth.start(3, cfg)
    state = truth.update(state, _situation(0.0, None, None, np.full(3, 30.0)), 0.1, cfg)
    assert state.count.tolist() == [1, 1, 1]  # the observed belief is still kept
    np.testing.assert_array_equal(truth.aggressive(state, _situation(0.0, 0, 0, 0, np.array([True, False, True]))),
                                  [True, False, True])  # fmt: skip
    with pytest.raises(ValueError, match=r"the 'truth' assessment needs Situation\.f_aggressive_truth"):
        truth.aggressive(state, _situation(0.0, 0, 0, 0, None))


def _slow_run(cfg, b=40, steps=60, dt=0.1, t0=0.0, seed=0):
    """Yielding followers (-1 m/s², far beyond the threshold) that move on every period, so that a redraw at a
    later observation would show; returns the per-step released belief and the keys of the first observation."""
    rng = np.random.default_rng(seed)
    f_x0, ego_x0, v0 = rng.uniform(-40.0, -10.0, b), rng.uniform(0.0, 5.0, b), rng.uniform(20.0, 30.0, b)
    slow = policies.ASSESSMENTS["slow"]
    state = slow.start(b, cfg)
    assert state.aggressive.all() and not state.missed.any() and (state.delay_s == 0.0).all()
    beliefs, firsts = [], []
    for k in range(steps):
        t = t0 + k * dt
        speed = v0 - 1.0 * k * dt
        sit = _situation(t, f_x0 + speed * t, ego_x0 + 30.0 * t, speed)
        if k == 0:
            key = (sit.f_x - sit.ego_x, sit.observed_f_speed)
        state = slow.update(state, sit, dt, cfg)
        beliefs.append(slow.aggressive(state, sit).copy())
        firsts.append(state.first_collaborative_s.copy())
    return state, np.array(beliefs), np.array(firsts), key


@pytest.mark.parametrize(("delay_s", "miss"), [(1.5, 0.0), (0.7, 0.5), (3.0, 1.0)])
def test_slow_assessment_releases_after_its_draw_and_misses_at_its_rate(delay_s, miss):
    dt, window, t0 = 0.1, 5, 2.0
    cfg = ShieldConfig(assessment="slow", assess_delay_s=delay_s, assess_miss=miss, assess_window=window)
    state, beliefs, firsts, (key_x, key_v) = _slow_run(cfg, dt=dt, t0=t0)
    u1 = np.array([_ref_uniform(x, v, 1) for x, v in zip(key_x, key_v, strict=True)])
    u2 = np.array([_ref_uniform(x, v, 2) for x, v in zip(key_x, key_v, strict=True)])
    delay = delay_s * (0.5 + u1)
    missed = u2 < miss
    np.testing.assert_allclose(state.delay_s, delay, rtol=1e-15)
    np.testing.assert_array_equal(state.missed, missed)
    t_verdict = t0 + (window - 1) * dt  # the observed belief turns collaborative at the first full window
    np.testing.assert_allclose(state.inner.first_collaborative_s, t_verdict, rtol=0, atol=1e-12)
    times = t0 + np.arange(len(beliefs)) * dt
    released = (times[:, None] - t_verdict) >= delay[None, :] - 1e-9
    expected = missed[None, :] | ~released
    np.testing.assert_array_equal(beliefs, expected)
    expected_first = np.where(expected, np.nan, t_verdict + delay[None, :])
    np.testing.assert_allclose(firsts, expected_first, rtol=0, atol=1e-12)
    if miss == 1.0:
        assert beliefs.all()
    elif miss == 0.0:
        assert not beliefs[-1].any()  # every collaborative F recognised within the horizon
    else:
        assert 0 < missed.sum() < len(missed)


def test_slow_assessment_without_delay_releases_at_the_verdict_itself():
    """assess_delay_s = 0: the verdict is released in the period it is reached (the tolerance is inclusive)."""
    dt, window = 0.1, 4
    cfg = ShieldConfig(assessment="slow", assess_delay_s=0.0, assess_window=window)
    _, beliefs, firsts, _ = _slow_run(cfg, steps=12, dt=dt)
    assert beliefs[: window - 1].all() and not beliefs[window - 1 :].any()
    np.testing.assert_allclose(firsts[window - 1], (window - 1) * dt, rtol=0, atol=1e-12)


def test_slow_release_boundary_is_inclusive_to_a_nanosecond():
    """A delay tuned bit by bit so that ``elapsed == delay - 1e-9`` exactly at one period: released there."""
    dt, window = 0.125, 3  # exact binary times
    key_x, key_v = -20.0, 25.0
    u1 = _ref_uniform(key_x, key_v, 1)
    elapsed = 0.75  # 6 periods after the verdict
    scale = None
    target = elapsed + 1e-9
    for _ in range(40):  # a delay D with D - 1e-9 == elapsed in floats, and a scale giving exactly D
        if target - 1e-9 == elapsed:
            guess = target / (0.5 + u1)
            for cand in (guess, *np.nextafter(guess, [np.inf, -np.inf])):
                if cand * (0.5 + u1) == target:
                    scale = float(cand)
        if scale is not None:
            break
        target = np.nextafter(target, np.inf)
    assert scale is not None
    cfg = ShieldConfig(assessment="slow", assess_delay_s=scale, assess_window=window)
    slow = policies.ASSESSMENTS["slow"]
    state = slow.start(1, cfg)
    out = []
    for k in range(window + 9):
        t = k * dt
        speed = np.array([key_v - 2.0 * t])
        # F's position relative to the ego is the key at the first observation; it moves afterwards.
        sit = _situation(t, np.array([key_x + 1.0 + k]), np.array([1.0]), speed)
        state = slow.update(state, sit, dt, cfg)
        out.append(bool(state.aggressive[0]))
    verdict = window - 1
    assert out == [True] * (verdict + 6) + [False] * (len(out) - verdict - 6)


def test_variant_flags_from_names_arrays_and_indices():
    want = np.array([[v.uses_chain, v.uses_follower_v2x, v.uses_assessment] for v in VARIANTS.values()])
    for i, name in enumerate(VARIANT_NAMES):
        flags = policies.variant_flags(name, 3)
        for col in range(3):
            assert flags[col].shape == (3,) and (flags[col] == want[i, col]).all()
    names = np.array(["CV_none", "CV_all", "No_agg_assess", "CV_follow", "CV_all"])
    idx = np.array([VARIANT_NAMES.index(n) for n in names])
    for variant in (names, list(names), idx, idx.astype(np.uint8)):
        flags = policies.variant_flags(variant, 5)
        for col in range(3):
            np.testing.assert_array_equal(flags[col], want[idx, col])
    empty = policies.variant_flags(np.array([], np.int64), 0)
    assert all(f.shape == (0,) for f in empty)
    last = len(VARIANT_NAMES) - 1
    np.testing.assert_array_equal(policies.variant_flags(np.array([0, last]), 2)[0], want[[0, last], 0])


def test_variant_flags_refuse_bad_variants():
    last = len(VARIANT_NAMES) - 1
    with pytest.raises(ValueError, match="unknown planner variant 'CV_some'"):
        policies.variant_flags("CV_some", 2)
    with pytest.raises(ValueError, match="unknown planner variant 'nope'"):
        policies.variant_flags(np.array(["CV_all", "nope"]), 2)
    with pytest.raises(ValueError, match="unknown planner variant 'nope'"):
        policies.variant_flags(np.array([b"CV_all", b"nope"]).astype(str), 2)
    for bad in ([0, last + 1], [-1, 0], [0, 99]):
        with pytest.raises(ValueError, match=rf"variant indices must lie in \[0, {last}\]; got \[{bad[0]}, {bad[1]}\]"):
            policies.variant_flags(np.array(bad), 2)
    for bad in (np.array([0.0, 1.0]), np.array([True, False]), 3.0):
        with pytest.raises(TypeError, match="variant must be a name or an array of names or indices"):
            policies.variant_flags(bad, 2)
    with pytest.raises(ValueError, match=r"variant must have one entry per row \(3\); got shape \(2,\)"):
        policies.variant_flags(np.array([0, 1]), 3)
    with pytest.raises(ValueError, match=r"one entry per row \(2\); got shape \(3,\)"):
        policies.variant_flags(np.array(["CV_all"] * 3), 2)


def test_check_policy_and_the_registries():
    assert policies.check_policy("thing", "b", {"a": 1, "b": 2}) == "b"
    with pytest.raises(ValueError, match="unknown thing 'c'; choose one of a, b"):
        policies.check_policy("thing", "c", {"a": 1, "b": 2})
    assert set(policies.ASSESSMENTS) == {"observed", "truth", "slow"}
    assert policies.COMPLETION_RULES == {"commit_guard": commit_guard, "paper_evasion": policies.paper_evasion,
                                         "paper_body_across": policies.paper_body_across}  # fmt: skip
    choices = "commit_guard, paper_evasion, paper_body_across"
    with pytest.raises(ValueError, match=f"unknown completion rule 'fast'; choose one of {choices}"):
        ShieldConfig(completion="fast")
    assert ShieldConfig(completion="paper_evasion").completion == "paper_evasion"


def test_paper_evasion_accepts_every_crossing_row_and_asks_for_the_evasion_check():
    for n in (0, 1, 4):
        z = np.zeros(n)
        out = policies.paper_evasion(z, z, z, z, z, z, z, None)
        assert out.dtype == bool and out.shape == (n,) and out.all()
    assert policies.paper_evasion.needs_evasion is True
    assert not getattr(commit_guard, "needs_evasion", False)


def test_paper_body_across_accepts_every_completing_row_and_completes_with_the_whole_car_across():
    rule = policies.paper_body_across
    for n in (0, 1, 4):
        z = np.zeros(n)
        out = rule(z, z, z, z, z, z, z, None)
        assert out.dtype == bool and out.shape == (n,) and out.all()
    assert rule.needs_evasion is True
    prm = Params(lane_width=4.0, vehicle_width=2.0)
    assert rule.level(prm) == 2.0 + 1.0  # the boundary (lane_width / 2) plus half the car
    assert not hasattr(policies.paper_evasion, "level") and not hasattr(commit_guard, "level")


def _key_drawing_zero(salt: int, v0: float = 25.0) -> float:
    """A key ``x0`` whose draw is exactly 0.0: the finaliser maps 0 to 0, so ``bits(x0)·φ = bits(v0) + salt``
    (mod 2⁶⁴), solved with φ's inverse; ``v0`` is nudged until ``x0`` is a finite float."""
    phi_inv = pow(0x9E3779B97F4A7C15, -1, 1 << 64)
    while True:
        bits = ((_bits(v0) + salt) * phi_inv) & MASK
        x0 = struct.unpack("<d", struct.pack("<Q", bits))[0]
        if np.isfinite(x0):
            return x0, v0
        v0 = float(np.nextafter(v0, np.inf))


def test_a_zero_miss_rate_never_misses_even_a_zero_draw():
    """P(miss) = assess_miss exactly: a draw u₂ uniform on [0, 1) misses where u₂ < assess_miss, so at
    assess_miss = 0 nothing is missed — also the one key whose draw is exactly 0.0."""
    x0, v0 = _key_drawing_zero(2)
    assert _ref_uniform(x0, v0, 2) == 0.0 and policies._scenario_uniform(np.array([x0]), np.array([v0]), 2)[0] == 0.0
    cfg = ShieldConfig(assessment="slow", assess_delay_s=0.0, assess_miss=0.0, assess_window=2)
    slow = policies.ASSESSMENTS["slow"]
    state = slow.start(1, cfg)
    for k in range(4):  # F yields: collaborative from the first full window on, released at once
        sit = _situation(0.1 * k, np.array([x0]), np.array([0.0]), np.array([v0 - 0.5 * k]))
        state = slow.update(state, sit, 0.1, cfg)
    assert not state.missed[0] and not slow.aggressive(state, sit)[0]
    cfg_all = ShieldConfig(assessment="slow", assess_delay_s=0.0, assess_miss=1e-300, assess_window=2)
    state = slow.update(slow.start(1, cfg_all), _situation(0.0, np.array([x0]), np.array([0.0]), np.array([v0])), 0.1,
                        cfg_all)  # fmt: skip
    assert state.missed[0]  # the zero draw is below any positive rate


def test_the_draw_depends_on_the_value_not_the_dtype_of_the_key():
    x = [-20.0, -31.5, -7.25]
    v = [25.0, 30.0, 12.0]
    ref = policies._scenario_uniform(np.array(x), np.array(v), 1)
    for xs, vs in ((x, v), ([-20, -31.5, -7.25], [25, 30, 12]), (np.array(x, np.float32), np.array(v, np.float32))):
        np.testing.assert_array_equal(policies._scenario_uniform(xs, vs, 1), ref)
    ints = policies._scenario_uniform(np.array([-20, -31, -7]), np.array([25, 30, 12]), 1)
    np.testing.assert_array_equal(ints, policies._scenario_uniform(np.array([-20.0, -31.0, -7.0]), np.array(v), 1))


def test_slow_states_are_boolean_beliefs():
    cfg = ShieldConfig(assessment="slow", assess_miss=0.5)
    slow = policies.ASSESSMENTS["slow"]
    start = slow.start(5, cfg)
    sit = _situation(0.0, np.linspace(-30, -10, 5), np.zeros(5), np.full(5, 25.0))
    assert slow.aggressive(start, sit).dtype == bool and start.missed.dtype == bool
    np.testing.assert_array_equal(start.first_collaborative_s, np.full(5, np.nan))
    state = start
    for k in range(3):
        state = slow.update(state, _situation(0.1 * k, sit.f_x, sit.ego_x, sit.observed_f_speed), 0.1, cfg)
        assert state.aggressive.dtype == bool and state.missed.dtype == bool and state.delay_s.dtype == float
