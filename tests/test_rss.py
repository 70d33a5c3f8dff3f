"""The RSS baseline: parameters, the NumPy closed forms (golden cases, shapes, an independent numeric check of the
V2X extension), parity with ad-rss itself on 10,000 random situations, and the RSS variants in the shield and the
simulator (the paper's variants untouched)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydantic import ValidationError
from typer.testing import CliRunner

from safelane import Params
from safelane.baselines import rss_adrss
from safelane.baselines.rss import (
    RssParams,
    lateral_safe_distance,
    longitudinal_safe_distance,
    longitudinal_safe_distance_exact,
    pair_check,
    rss_params_for,
)
from safelane.cli import app
from safelane.planners.variants import PAPER_VARIANT_NAMES, VARIANT_NAMES
from safelane.shield.rules import DECISION_RULES, rule_rows
from safelane.sim import concat, paper_scenarios, simulate_batch

PRM = Params()
RSS_VARIANTS = [name for name in VARIANT_NAMES if name not in PAPER_VARIANT_NAMES]


# ---------------------------------------------------------------- parameters
def test_defaults_are_ad_rss_documented_starting_values():
    p = RssParams()
    assert (p.response_time_ego, p.response_time_other) == (1.0, 2.0)
    assert (p.accel_max, p.brake_min, p.brake_max, p.brake_min_correct) == (3.5, 4.0, 8.0, 3.0)
    assert (p.lat_accel_max, p.lat_brake_min, p.lateral_fluctuation_margin) == (0.2, 0.8, 0.1)


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"brake_min": 9.0}, "brake_min=9.0 must not exceed brake_max=8.0"),
        ({"brake_min_correct": 5.0}, "brake_min_correct=5.0 must not exceed brake_min=4.0"),
        ({"response_time_ego": 0.0}, "response_time_ego"),
        ({"lat_brake_min": -1.0}, "lat_brake_min"),
        ({"accel_max": float("nan")}, "accel_max"),
        ({"brake_mni": 4.0}, "brake_mni"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, needle):
    with pytest.raises(ValidationError, match=needle):
        RssParams(**kwargs)


def test_parameter_sets():
    assert rss_params_for("ad_rss", PRM) == RssParams()
    matched = rss_params_for("matched", PRM)
    assert matched.response_time_ego == PRM.dt and matched.brake_min == matched.brake_max == PRM.a_x_d
    with pytest.raises(ValueError, match="unknown RSS parameter set 'x'; choose one of ad_rss, matched"):
        rss_params_for("x", PRM)


# ---------------------------------------------------------------- the closed forms
def test_golden_longitudinal_and_lateral():
    # Rear at 30 m/s, ρ = 1 s: 30 + 1.75 + 33.5²/8 = 172.03125 m; front at 20 m/s stops in 20²/16 = 25 m.
    assert longitudinal_safe_distance(20.0, 30.0, 1.0, 3.5, 4.0, 8.0) == pytest.approx(147.03125, abs=1e-12)
    # Left at 0.5 m/s (ρ 2 s): 1.4 + 0.9²/1.6; right at -0.3 m/s towards it (ρ 1 s): 0.4 + 0.5²/1.6; μ 0.1.
    expected = (0.4 + 1.0 + 0.81 / 1.6) + (0.1 + 0.3 + 0.25 / 1.6) + 0.1
    assert lateral_safe_distance(0.5, 2.0, -0.3, 1.0, 0.2, 0.8, 0.1) == pytest.approx(expected, abs=1e-12)
    # A front vehicle much faster: no distance needed (clamped at 0).
    assert longitudinal_safe_distance(40.0, 0.0, 1.0, 3.5, 4.0, 8.0) == 0.0


@pytest.mark.parametrize("shape", [(), (4,), (2, 3)])
def test_shapes(shape):
    rng = np.random.default_rng(1)
    v = rng.uniform(0, 40, shape)
    assert np.shape(longitudinal_safe_distance(v, v, 1.0, 3.5, 4.0, 8.0)) == shape
    assert np.shape(longitudinal_safe_distance_exact(v, v, 1.0, 3.5, 4.0, 2.0)) == shape
    assert np.shape(lateral_safe_distance(v / 40, 2.0, -v / 40, 1.0, 0.2, 0.8, 0.1)) == shape
    out = pair_check(0.0, 0.0, v, 0.0, 20.0, 3.5, v, 0.0, RssParams(), PRM)
    assert all(np.shape(o) == shape for o in out)


def _closing_max_numeric(v_f, v_r, rho, a, b_r, b_f, steps=20001):
    """The largest closing of a worst-case rear vehicle on a front one, by evaluating both motions on a fine grid."""
    t_end = np.maximum(v_f / b_f, rho + (v_r + a * rho) / b_r)
    t = np.linspace(0.0, 1.0, steps)[None, :] * t_end[:, None]
    tf = np.minimum(t, (v_f / b_f)[:, None])
    x_f = v_f[:, None] * tf - 0.5 * b_f[:, None] * tf * tf
    t1 = np.minimum(t, rho)
    v_rho = v_r + a * rho
    t2 = np.clip(t - rho, 0.0, (v_rho / b_r)[:, None])
    x_r = v_r[:, None] * t1 + 0.5 * a * t1 * t1 + v_rho[:, None] * t2 - 0.5 * b_r * t2 * t2
    return np.maximum((x_r - x_f).max(1), 0.0)


def test_v2x_extension_is_the_exact_worst_case_closing():
    # With a front vehicle braking less than brake_min (a promised V2X bound), the largest closing can come before
    # both stop; the exact form must match a brute-force maximum, and never be below ad-rss's closed form.
    rng = np.random.default_rng(2)
    n = 200
    v_f, v_r = rng.uniform(0, 40, n), rng.uniform(0, 40, n)
    b_f = rng.uniform(0.3, 8.0, n)
    rho, a, b_r = 0.5, 2.5, 8.0
    exact = longitudinal_safe_distance_exact(v_f, v_r, rho, a, b_r, b_f)
    numeric = _closing_max_numeric(v_f, v_r, rho, a, b_r, b_f)
    assert np.max(np.abs(exact - numeric)) < 1e-3
    assert np.all(exact >= longitudinal_safe_distance(v_f, v_r, rho, a, b_r, b_f) - 1e-12)
    assert np.any(exact > longitudinal_safe_distance(v_f, v_r, rho, a, b_r, b_f) + 1.0)  # the case matters
    same = b_f >= b_r  # where RSS's lemma holds, nothing changes
    assert np.array_equal(exact[same], longitudinal_safe_distance(v_f, v_r, rho, a, b_r, b_f)[same])


# ---------------------------------------------------------------- parity with ad-rss
def _random_situations(rng, n, rss: RssParams):
    """Ego and another vehicle: ego in front and behind, other left/right/same lane, stopped vehicles, zero gaps,
    and distances within a few millimetres of the safe distance (ad-rss compares to 1 mm)."""
    ex, ey = np.zeros(n), rng.uniform(0.0, 3.5, n)
    evx, evy = rng.uniform(0.0, 40.0, n), rng.uniform(-2.0, 2.0, n)
    vx, vy = rng.uniform(0.0, 40.0, n), rng.uniform(-1.0, 1.0, n)
    y = rng.choice([0.0, 3.5, 7.0], n) + rng.uniform(-0.5, 0.5, n) * (rng.uniform(size=n) < 0.3)
    x = rng.uniform(-150.0, 150.0, n)
    k = rng.uniform(size=n)
    vx[k < 0.1], evx[(k > 0.1) & (k < 0.2)] = 0.0, 0.0  # stopped vehicles
    evy[(k > 0.2) & (k < 0.3)], vy[(k > 0.25) & (k < 0.35)] = 0.0, 0.0
    sign = np.where(rng.uniform(size=n) < 0.5, 1.0, -1.0)
    x = np.where((k > 0.35) & (k < 0.4), sign * PRM.vehicle_length, x)  # zero longitudinal gap
    y = np.where((k > 0.4) & (k < 0.45), ey + sign * PRM.vehicle_width, y)  # zero lateral gap
    brake_other = np.where(rng.uniform(size=n) < 0.5, rss.brake_max, rng.uniform(rss.brake_min, 2 * rss.brake_max, n))
    # Near the threshold: put the other vehicle at the safe distance plus a few tenths of the 1 mm precision.
    near = (k > 0.45) & (k < 0.7)
    safe = pair_check(ex, ey, evx, evy, x, y, vx, vy, rss, PRM, brake_other)[4]
    delta = rng.choice([-2e-3, -1e-3, -5e-4, 0.0, 5e-4, 1e-3, 1.5e-3, 1e-2], n)
    x = np.where(near, np.sign(x) * (PRM.vehicle_length + safe + delta), x)
    return ex, ey, evx, evy, x, y, vx, vy, brake_other


def _parameter_sets(rng):
    sets = [RssParams(), rss_params_for("matched", PRM)]
    for _ in range(3):
        b_max = rng.uniform(4.0, 10.0)
        b_min = rng.uniform(1.0, b_max)
        sets.append(RssParams(response_time_ego=rng.uniform(0.1, 2.0), response_time_other=rng.uniform(0.1, 3.0),
                              accel_max=rng.uniform(0.5, 5.0), brake_min=b_min, brake_max=b_max,
                              brake_min_correct=rng.uniform(0.5, b_min), lat_accel_max=rng.uniform(0.1, 2.0),
                              lat_brake_min=rng.uniform(0.2, 2.0), lateral_fluctuation_margin=rng.uniform(0.0, 0.3),
                              max_speed_on_acceleration=rng.uniform(20.0, 60.0),
                              min_longitudinal_safety_distance=rng.uniform(0.0, 2.0)))  # fmt: skip
    return sets


def test_numpy_matches_ad_rss_on_10000_random_situations():
    if not rss_adrss.available():
        pytest.skip("ad-rss is not installed (the extra 'rss': pip install -e '.[rss]'); CI installs it")
    rng = np.random.default_rng(16)
    total, worst = 0, 0.0
    for rss in _parameter_sets(rng):
        n = 2000
        situations = _random_situations(rng, n, rss)
        ours = pair_check(*situations[:8], rss, PRM, situations[8])
        for i in range(n):
            ref = rss_adrss.pair_check(*(float(a[i]) for a in situations[:8]), rss, PRM, float(situations[8][i]))
            assert tuple(bool(o[i]) for o in ours[:3]) == ref[:3], (i, rss, [a[i] for a in situations], ref)
            diffs = [abs(float(ours[k][i]) - ref[k]) for k in (3, 4, 5, 6)]
            worst = max(worst, *diffs)
            assert max(diffs) <= 1e-6, (i, rss, diffs)
        total += n
    assert total >= 10_000 and worst <= 1e-6


def test_ad_rss_wrapper_without_the_extra_names_the_install():
    assert "pip install" in rss_adrss.INSTALL_HINT and "rss" in rss_adrss.INSTALL_HINT


# ---------------------------------------------------------------- the variants in the shield and the simulator
def test_rule_rows_by_variant():
    assert rule_rows("CV_all", 3) == []
    (rule, rows), = rule_rows("RSS_V2X", 3)  # fmt: skip
    assert rule is DECISION_RULES["rss"] and rows.tolist() == [0, 1, 2]
    mixed = rule_rows(np.array([0, VARIANT_NAMES.index("RSS_matched"), 1, VARIANT_NAMES.index("RSS")]), 4)
    assert {repr(r): idx.tolist() for r, idx in mixed} == {"RssRule('ad_rss')": [3], "RssRule('matched')": [1]}


def test_paper_rows_are_unchanged_by_rss_rows_in_the_same_batch():
    rng = np.random.default_rng(3)
    paper = paper_scenarios("CV_all", 3, 5.0, 40, rng)
    rss = dataclasses.replace(paper, variant=np.full(40, VARIANT_NAMES.index("RSS_V2X_matched")))
    alone = simulate_batch(paper, seed=0).table
    mixed = simulate_batch(concat([paper, rss]), seed=0).table
    cols = [c for c in alone.columns if c != "scenario_id"]
    assert alone[cols].equals(mixed[cols].iloc[:40].reset_index(drop=True))
    assert (mixed["planner"].iloc[40:] == "RSS_V2X_matched").all()


@pytest.mark.parametrize("name", RSS_VARIANTS)
def test_rss_variants_run_from_the_command_line(name, tmp_path):
    result = CliRunner().invoke(app, ["simulate", "--planner", name, "--leaders", "3", "--decel", "4", "--samples",
                                      "20", "--seed", "0", "--out", str(tmp_path)])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert name in result.output


def test_rss_never_leaves_a_collaborative_world_in_collision():
    # Every vehicle inside RSS's assumptions here (F collaborative, leaders within their bounds): no collision.
    rng = np.random.default_rng(4)
    batches = [dataclasses.replace(paper_scenarios("CV_all", n, d, 60, rng),
                                   variant=np.full(60, VARIANT_NAMES.index(v)),
                                   follower_aggressive=np.zeros(60, bool))
               for v in RSS_VARIANTS for n, d in ((1, 4.0), (10, 6.0))]  # fmt: skip
    table = simulate_batch(concat(batches), seed=0).table
    assert not table["collision"].any()


def test_ad_rss_full_check_agrees_on_one_lane():
    # ad-rss's whole pipeline (RssCheck over a world model) against the NumPy verdict, ego in front and behind.
    if not rss_adrss.available():
        pytest.skip("ad-rss is not installed (the extra 'rss': pip install -e '.[rss]'); CI installs it")
    import ad_rss

    rng = np.random.default_rng(5)
    checker = ad_rss.rss.core.RssCheck()
    rss = RssParams()
    for i in range(150):
        ego_v, other_v, gap = rng.uniform(0, 40), rng.uniform(0, 40), rng.uniform(-200, 200)
        x = gap + PRM.vehicle_length if gap >= 0 else gap - PRM.vehicle_length
        ours = bool(pair_check(0.0, 0.0, ego_v, 0.0, x, 0.0, other_v, 0.0, rss, PRM)[0])
        model = rss_adrss.same_lane_world(ego_v, other_v, gap, rss, PRM, object_id=i + 1, time_index=i + 1)
        assert rss_adrss.full_check(checker, model) == ours, (ego_v, other_v, gap)


def test_rss_baseline_experiment_table_and_paragraph():
    from safelane.experiments.rss_baseline import RssBaselineConfig, overview
    from safelane.experiments.runner import run_experiment
    from safelane.reporting.rss import paragraph

    cfg = RssBaselineConfig(samples=4, n_leaders=(3,), decels=(4.0,))
    res = run_experiment("rss_baseline", cfg)
    assert set(res.table["follower"]) == {"collaborative", "aggressive", "ignores_ego"}
    assert len(res.table) == 3 * len(VARIANT_NAMES) * 4
    view = overview(res.summary)
    assert len(view) == 3 * len(VARIANT_NAMES) and (view["samples"] == 4).all()
    text = paragraph(view)
    assert "CV_all completes" in text and "ad-rss's default parameters" in text and "%" in text


@pytest.mark.parametrize("name", ["RSS_matched", "RSS"])
def test_the_rss_rule_keeps_its_distance_to_the_own_lanes_leader(name):
    """RSS's longitudinal rule holds toward L0, the leader in the ego's own lane, until the change completes: with L0
    7 m ahead (a 2.2 m bumper gap, far inside any RSS safe distance at 25 m/s) a full-throttle proposal gets the
    proper response (braking at brake_min or more); with L0 300 m ahead, or none, it proceeds. (The rule ignored L0:
    on stock highway-v0 6 of the first 16 episodes ran into it.)"""
    from safelane.shield import ABORT, PROCEED, Shield, Situation

    prm = Params()

    def decide(own):
        s = Situation.from_arrays(t=0.0, ego=(0.0, 0.0, 25.0, 0.0), follower=(-150.0, 25.0),
                                  leaders=([150.0, 170.0], [25.0, 25.0]), n_connected=0, params=prm,
                                  own_leaders=own)  # fmt: skip
        shield = Shield(prm, variant=name)
        shield.reset(s)
        return shield.step(s, (np.array([prm.a_x_a]), np.array([0.0])))

    near = decide(([7.0], [25.0]))
    assert near.behaviour[0] == ABORT and near.a_x[0] < 0.0
    for own in (([300.0], [25.0]), ([np.inf], [0.0]), None):
        d = decide(own)
        assert d.behaviour[0] == PROCEED and d.a_x[0] == prm.a_x_a
