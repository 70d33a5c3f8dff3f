"""The adversarial falsifier: deterministic, able to fail outside the assumptions, replayable; its planners."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.experiments import falsify_build as built
from safelane.experiments import falsify_space as space
from safelane.experiments.falsify import OUTCOMES, Setting, falsify, replay
from safelane.planners.adversarial import ADVERSARIES, HugLeader, Mixture, Oscillating
from safelane.planners.base import Observation
from safelane.sim import SimConfig

PRM = Params()
SHORT = SimConfig(assessment="truth", horizon_s=4.0)


def _summary(report):
    s = report.summary()
    s.pop("wall_s")
    return s


def _observation(n: int, rng: np.random.Generator, t: float = 0.35) -> Observation:
    u = lambda lo, hi: rng.uniform(lo, hi, size=n)  # noqa: E731
    return Observation(
        p_x=u(-5, 5), p_y=u(0, 3.5), v_x=u(0, 40), v_y=u(-1, 1), p_x_l=u(10, 40), v_x_l=u(0, 40), p_x_f=u(-40, -10),
        v_x_f=u(0, 40), l1_plan=np.zeros((n, 10)), l1_connected=np.ones(n, bool), f_connected=np.ones(n, bool),
        completed=np.zeros(n, bool), t=t,
    )  # fmt: skip


def test_same_seed_same_report():
    setting = Setting(sim=SHORT)
    a = falsify(200, seed=3, method="all", batch_size=256, setting=setting)
    b = falsify(200, seed=3, method="all", batch_size=256, setting=setting)
    assert _summary(a) == _summary(b)
    assert a.worst == b.worst
    assert a.simulated >= 200 and a.generated % (3 * 256) == 0  # whole rounds of one batch per method
    c = falsify(200, seed=4, method="all", batch_size=256, setting=setting)
    assert _summary(c) != _summary(a)


def test_it_can_fail_without_the_supervisor():
    setting = Setting(sim=SimConfig(assessment="truth", horizon_s=4.0, supervised=False))
    report = falsify(100, seed=0, method="random", batch_size=256, setting=setting)
    assert report.counts["collision"] + report.counts["safety_violation"] > 0
    assert report.min_ratio < 1.0 and report.failures
    # A dumped failure replays to the same outcome.
    record = report.failures[0]
    row = replay(record).iloc[0]
    for name in ("collision", "safety_violation", "leader_violation"):
        assert bool(row[name]) == record["outcome"][name]


def test_it_can_fail_when_the_last_leader_brakes_beyond_a_x_d():
    setting = Setting(sim=SHORT, decel_last_max=3 * PRM.a_x_d)
    report = falsify(200, seed=0, method="random", batch_size=512, setting=setting)
    assert sum(report.counts[name] for name in OUTCOMES) > 0


def test_decoded_and_knife_specs_build_inside_the_assumptions():
    rng = np.random.default_rng(0)
    u = rng.uniform(size=(300, space.dimension(PRM)))
    for spec in (space.decode(u, PRM), space.knife_specs(rng, 300, PRM)):
        assert np.all(spec["n"] <= space.MAX_N) and np.all(spec["n"] >= 0)
        assert np.all(np.diff(spec["profile_t"], axis=1) >= PRM.dt - 1e-12)  # at most one switch per period
        assert np.all((spec["profile_a"] >= -PRM.a_x_d) & (spec["profile_a"] <= PRM.a_x_a))
        batch, ok = built.build(spec, PRM, profiles=built.with_profile_fields())
        assert 0 < ok.sum() < len(ok)  # some rows are dropped at t = 0, many kept
        assert np.all(batch.v >= 0.0)
    knife = space.knife_specs(np.random.default_rng(1), 400, PRM)
    assert (knife["slack"] == 0.0).any() and (knife["l1_slack"] == 0.0).any()


@pytest.mark.parametrize("name", sorted(ADVERSARIES))
def test_adversarial_planners_give_finite_actions_of_the_batch_shape(name):
    rng = np.random.default_rng(2)
    obs = _observation(7, rng)
    a_x, a_y = ADVERSARIES[name]()(obs, PRM)
    for a, limit in ((a_x, max(PRM.a_x_a, PRM.a_x_d)), (a_y, PRM.a_y_m)):
        assert a.shape == (7,) and np.isfinite(a).all() and np.abs(a).max() <= limit


def test_per_scenario_parameters_are_row_aligned():
    rng = np.random.default_rng(3)
    obs = _observation(4, rng)
    offsets = np.array([0.0, 1.0, 2.0, 3.0])
    a_x, _ = HugLeader(offset_m=offsets, k_p=0.01, k_v=0.0)(obs, PRM)
    expected = 0.01 * (obs.p_x_l - PRM.p_m - offsets - obs.p_x)
    np.testing.assert_allclose(a_x, np.clip(expected, -PRM.a_x_d, PRM.a_x_a))
    with pytest.raises(ValueError, match="workers=1"):
        HugLeader(offset_m=np.zeros(3))(obs, PRM)
    mix = Mixture((HugLeader(), Oscillating()), choice=np.array([0, 1, 1, 0]))
    m_x, _ = mix(obs, PRM)
    np.testing.assert_array_equal(m_x[[0, 3]], HugLeader()(obs, PRM)[0][[0, 3]])
    np.testing.assert_array_equal(m_x[[1, 2]], Oscillating()(obs, PRM)[0][[1, 2]])


def test_merged_streams_add_up_and_keep_the_worst():
    from safelane.experiments.falsify import Report, merge

    a = Report(seed=0, methods=("random",), hooks=True, profiles=True, generated=10, simulated=4, min_ratio=1.2)
    b = Report(seed=0, methods=("random",), hooks=True, profiles=True, generated=6, simulated=3, min_ratio=1.1)
    a.counts["collision"], b.counts["collision"] = 1, 2
    a.by_method = {"random": {"generated": 10, "simulated": 4, "min_ratio": 1.2, "failures": 1}}
    b.by_method = {"random": {"generated": 6, "simulated": 3, "min_ratio": 1.1, "failures": 2}}
    b.worst = {"spec": {}}
    m = merge([a, b])
    assert (m.generated, m.simulated, m.counts["collision"], m.min_ratio) == (16, 7, 3, 1.1)
    assert m.worst is b.worst and m.by_method["random"]["failures"] == 3


def test_realistic_worst_scenario_replays_exactly():
    """The closest scenario of the million-scenario realistic-world search (docs/real_roads.md) replays to the same
    gap, bit for bit: L0, the measurement errors (keyed by the spec) and the delay are part of the dump."""
    import json
    from pathlib import Path

    from safelane.experiments import falsify as fz

    path = Path(__file__).parent.parent / "docs" / "falsification" / "realistic_worst.json"
    record = json.loads(path.read_text())
    row = fz.replay(record).iloc[0]
    assert "l0_present" in record["spec"] and "delay_periods" in record["spec"]
    assert row["ratio"] == record["outcome"]["ratio"]
    assert not row[list(fz.OUTCOMES)].any()


def test_scenarios_with_a_flagged_breach_are_kept_and_replay_to_the_flag(tmp_path):
    """Outside the assumptions (L(N+1) braking beyond a_x_d) the monitor flags breaches; each flagged scenario is
    dumped (``breach_<i>.json``), replays to a flag of its own, and merging streams keeps them."""
    import json

    from safelane.experiments.falsify import merge

    setting = Setting(sim=SHORT, decel_last_max=3 * PRM.a_x_d)
    report = falsify(200, seed=0, method="random", batch_size=512, setting=setting)
    assert 0 < len(report.breaches) <= min(20, report.counts["assumption_breach"])
    for record in report.breaches[:3]:
        assert record["outcome"]["assumption_breach"] > 0
        assert replay(record).iloc[0]["assumption_breach"] == record["outcome"]["assumption_breach"]
    written = [p.name for p in report.write(tmp_path)]
    assert [f"breach_{i}.json" for i in range(len(report.breaches))] == [n for n in written if n.startswith("breach")]
    assert json.loads((tmp_path / "breach_0.json").read_text()) == report.breaches[0]
    assert merge([report, report]).breaches == (report.breaches * 2)[:20]
