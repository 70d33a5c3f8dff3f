"""The compiled closed loop (:mod:`safelane.sim._fast_loop`, numba; its Python side :mod:`safelane.sim._fused`) against
the loop period by period: the same per-scenario table, column for column and bit for bit, as the period-by-period
path with its part kernels (``SAFELANE_NO_FUSED=1``) and as the NumPy path (``SAFELANE_NO_NUMBA=1``), on batches
that exercise every branch (the four variants, aggressive and collaborative F, hesitations, aborts on the held plan,
completions, breaches of the assumptions, human-driven leaders), with non-default parameters, settings and planner;
the dispatch (the loop runs exactly where it covers the settings) and its failure path."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.planners.base import ExpertPlanner
from safelane.shield.rules import DECISION_RULES, Coded
from safelane.sim import ScenarioConfig, SimConfig, _fused, concat, paper_scenarios, simulate_batch
from safelane.sim._stepper import steps_compiled
from test_fast_core import needs_numba

pytestmark = [pytest.mark.compiled, needs_numba]

VARIANTS = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
MIXED_F = ScenarioConfig(follower_connected_share=0.5)  # non-connected followers, half of them aggressive


def _mixed(n_leaders, decel, per_variant=120, scenario=MIXED_F, seed=0):
    return concat([paper_scenarios(v, n_leaders, decel, per_variant, np.random.default_rng(100 * seed + k), scenario,
                                   first_id=1000 * k) for k, v in enumerate(VARIANTS)])  # fmt: skip


def _three_paths(monkeypatch, batch, **kwargs):
    """``(fused, period by period, NumPy path)`` tables, and how often the fused loop ran."""
    calls = []
    real = _fused.run_chunk
    monkeypatch.setattr(_fused, "run_chunk", lambda *a: calls.append(1) or real(*a))
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    fused = simulate_batch(batch, seed=4, **kwargs).table
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    periods = simulate_batch(batch, seed=4, **kwargs).table
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = simulate_batch(batch, seed=4, **kwargs).table
    return fused, periods, reference, len(calls)


CASES = {
    "N = 3, a_N+1 = 5": (lambda: _mixed(3, 5.0), {}),
    "N = 1, a_N+1 = 9 > a_x_d (breaches)": (lambda: _mixed(1, 9.0, seed=1), {}),
    "unexpected promise violations (p_v = 0.05)": (
        lambda: concat([paper_scenarios(v, 3, 5.0, 60, np.random.default_rng(30 + k), MIXED_F, p_v=0.05,
                                        first_id=1000 * k) for k, v in enumerate(VARIANTS)]),
        {},
    ),
    "unexpected promise violations (p_v = 0.05), reactive leaders": (
        lambda: concat([paper_scenarios(v, 3, 5.0, 60, np.random.default_rng(40 + k), MIXED_F, p_v=0.05,
                                        first_id=1000 * k) for k, v in enumerate(VARIANTS)]),
        dict(config=SimConfig(leader_rule="reactive")),
    ),
    "reactive leaders, N = 5, a_N+1 = 7": (
        lambda: _mixed(5, 7.0, seed=6),
        dict(config=SimConfig(leader_rule="reactive")),
    ),
    "N = 5, a_N+1 = 3, human-driven leaders": (
        lambda: _mixed(5, 3.0, scenario=ScenarioConfig(follower_connected_share=0.5, human_share=0.5)),
        {},
    ),
    "others brake harder than the ego commits to (a_o_d = 9.5, a_N+1 = 9)": (
        lambda: _mixed(3, 9.0, seed=3),
        dict(params=Params(a_o_d=9.5)),
    ),
    # the chain analysis runs before the shield and is given to it (sim/_fast_loop._period): links exactly at
    # their margin (human-driven leaders 10 m apart, p_m_human = 10) and inside it (unsafe from the start), beside
    # a batch of the paper's gaps (completions, assessments)
    "chains at and inside their links' margins (the chain given to the shield)": (
        lambda: concat([
            paper_scenarios(v, 3, 6.0, 40, np.random.default_rng(70 + k), ScenarioConfig(
                follower_connected_share=0.5, human_share=0.6, gap=(10.0, 10.0) if k % 2 else (9.6, 10.4)),
                first_id=1000 * k + 500)
            for k, v in enumerate(VARIANTS)
        ] + [_mixed(3, 6.0, per_variant=40, seed=7)]),
        {},
    ),
    "other parameters, settings and planner": (
        lambda: _mixed(2, 6.0, seed=2),
        dict(
            params=Params(a_x_a=2.0, a_x_d=7.0, a_y_m=1.2, p_m=6.0, p_m_human=9.0),
            config=SimConfig(
                horizon_s=6.0, brake_start_s=0.7, assess_window=7, assess_threshold=0.3, follower_open_decel=1.0,
                follower_open_gap_m=5.0, l1_plan_steps=4,
            ),
            nominal=ExpertPlanner(k_p=0.4, k_v=0.6, omega=0.8, gap_fraction=0.3, brake_comfort=3.0),
        ),
    ),
    "RSS's rule (both parameter sets, with and without V2X) beside the paper's variants": (
        lambda: concat([paper_scenarios(v, 3, 5.0, 60, np.random.default_rng(50 + k), MIXED_F, first_id=1000 * k)
                        for k, v in enumerate(("RSS", "RSS_V2X", "RSS_matched", "RSS_V2X_matched", "CV_all"))]),
        {},
    ),
    "F ignores the ego (RSS and the paper's variants)": (
        lambda: concat([paper_scenarios(v, 3, 4.0, 60, np.random.default_rng(60 + k), first_id=1000 * k)
                        for k, v in enumerate(("RSS_matched", "RSS_V2X", "CV_all", "CV_none"))]),
        dict(config=SimConfig(follower_ignores_ego=True)),
    ),
    "the paper preset's settings: its vehicles, slow assessment, completion rule, reactive leaders, monitor off": (
        lambda: _mixed(3, 6.0, seed=5),
        dict(params=Params(a_x_a=3.0, a_x_d=6.151, a_y_m=2.629, lane_width=3.5, vehicle_width=1.8, vehicle_length=4.8,
                           p_m=7.4, p_m_human=10.0),
             config=SimConfig(completion="paper_evasion", monitor=False, horizon_s=11.148, leader_rule="reactive",
                              assessment="slow", assess_delay_s=3.0, assess_miss=0.231)),
    ),
}


@pytest.mark.filterwarnings("ignore:a_x_N\\+1_d")
@pytest.mark.parametrize("case", list(CASES))
def test_the_fused_loop_gives_the_numpy_paths_table_bit_for_bit(monkeypatch, case):
    make, kwargs = CASES[case]
    batch = make()
    fused, periods, reference, calls = _three_paths(monkeypatch, batch, **kwargs)
    assert calls == 1
    assert fused.equals(periods) and fused.equals(reference), case
    # the batch exercises what the loop holds: every behaviour, completions, the assessment's verdicts
    assert (reference[["n_proceed", "n_hesitate", "n_abort"]].sum() > 0).all()
    if "RSS" not in case and "ignores" not in case:  # (RSS never assesses F; Fs that ignore the ego are connected)
        assert reference["assessed_aggressive"].any() and not reference["assessed_aggressive"].all()
    if case.startswith("RSS's rule"):  # RSS's rows proceed, hesitate and respond (aborts without a held plan)
        rss = batch.variant >= 4
        assert (reference[["n_proceed", "n_hesitate", "n_abort"]].to_numpy()[rss].sum(0) > 0).all()
    if "ignores" in case:  # the setting changes F's gaps (F closes in where it would have yielded)
        default = simulate_batch(batch, seed=4, config=SimConfig()).table["min_gap_follower_m"]
        changed = ~np.isclose(default, reference["min_gap_follower_m"], rtol=0.0, atol=1e-6, equal_nan=True)
        assert changed.sum() > len(batch) // 10, changed.sum()
    if "breaches" in case:  # L(N+1) beyond a_x_d: the monitor's flags; no gap is left to complete into
        assert reference["assumption_breach"].any() and reference["breach_time_s"].notna().any()
    elif "ignores" not in case:  # (an F that never yields leaves the expert no gap)
        assert reference["completed"].any() and not reference["completed"].all()


def test_progress_runs_the_fused_loop_in_chunks_with_the_same_table(monkeypatch):
    batch = _mixed(3, 5.0, per_variant=40)
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    whole = simulate_batch(batch, seed=1).table
    calls = []
    real = _fused.run_chunk
    monkeypatch.setattr(_fused, "run_chunk", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(_fused, "PROGRESS_CHUNK", 50)
    chunked = simulate_batch(batch, seed=1, progress=True).table
    assert len(calls) == 4  # 160 scenarios in chunks of at most 50
    assert chunked.equals(whole)


def _covers(batch, cfg=None, nominal=None, traffic=None, trace=False, record=False):
    return _fused.covers(batch, cfg or SimConfig(), nominal or ExpertPlanner(), traffic, trace, record)


def test_the_fused_loop_covers_the_default_settings_from_its_threshold_on(monkeypatch):
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.delenv("SAFELANE_NO_FUSED", raising=False)
    rows = _fused.FUSED_MIN_ROWS
    assert _covers(paper_scenarios("CV_all", 3, 5.0, rows, np.random.default_rng(0)))
    assert not _covers(paper_scenarios("CV_all", 3, 5.0, rows - 1, np.random.default_rng(0)))
    batch = paper_scenarios("CV_all", 3, 5.0, rows, np.random.default_rng(0))
    for name in ("SAFELANE_NO_FUSED", "SAFELANE_NO_NUMBA"):
        monkeypatch.setenv(name, "1")
        assert not _covers(batch), name
        monkeypatch.delenv(name)


UNCOVERED = {
    "a shield's actuation delay other than the world's": dict(
        cfg=SimConfig(actuation_delay_s=0.2, shield={"actuation_delay_s": 0.1})
    ),
    "V2X loss": dict(cfg=SimConfig(v2x_loss=0.1)),
    "V2X latency": dict(cfg=SimConfig(v2x_latency_periods=1)),
    "sensor noise": dict(cfg=SimConfig(sensor_noise_std=0.1)),
    "unsupervised": dict(cfg=SimConfig(supervised=False)),
    "the completion rule paper_body_across": dict(cfg=SimConfig(completion="paper_body_across")),
    "a traffic model": dict(traffic="paper"),
    "another planner": dict(nominal=lambda obs, prm: (np.zeros(len(obs.p_x)), np.zeros(len(obs.p_x)))),
    "a subclass of the expert": dict(nominal=type("Mine", (ExpertPlanner,), {})()),
    "a trace": dict(trace=True),
    "recorded observations": dict(record=True),
}


@pytest.mark.parametrize("case", list(UNCOVERED))
def test_the_fused_loop_leaves_every_other_setting_to_the_period_by_period_path(monkeypatch, case):
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.delenv("SAFELANE_NO_FUSED", raising=False)
    batch = paper_scenarios("CV_all", 3, 5.0, 80, np.random.default_rng(0))
    assert not _covers(batch, **UNCOVERED[case])


def test_the_fused_loop_runs_profiles_and_leaves_other_rules_to_the_period_by_period_path(monkeypatch):
    from safelane.sim.traffic import TrafficHooks, WaveHooks, with_last_profile

    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    monkeypatch.delenv("SAFELANE_NO_FUSED", raising=False)
    rng = np.random.default_rng(0)
    batch = paper_scenarios("CV_all", 3, 5.0, 80, rng)
    profiled = with_last_profile(batch, np.tile([0.0, 1.0], (80, 1)), np.tile([0.0, -5.0], (80, 1)))
    assert _covers(profiled)  # (tests/test_fast_profiles.py: the same bits)
    # Traffic hooks as data run in the loop and on its compiled period, callables on neither.
    waves = WaveHooks(**{name: np.zeros((80, 5)) for name in ("task_low", "task_span", "task_hi", "task_lo",
                                                              "task_phase")},
                      **{name: np.ones(80) for name in ("task_period", "f_period", "f_phase", "f_hi", "f_lo")})
    assert _covers(batch, traffic=waves)
    assert not steps_compiled(batch, SimConfig(), waves)
    assert steps_compiled(batch, SimConfig(), TrafficHooks(follower_wish=lambda view, prm: view.v[:, 0]))
    rss = concat([batch, paper_scenarios("RSS", 3, 5.0, 10, rng, first_id=500)])
    assert _covers(rss)  # RSS's rule is compiled (shield/_fast_rules.py); a user's own rule is not
    monkeypatch.setitem(DECISION_RULES, "rss", Coded(type("Mine", (), {"decide": lambda self, inp, prm: None})()))
    assert not _covers(rss)


def test_a_non_finite_state_raises_naming_the_scenarios_as_the_period_by_period_path(monkeypatch):
    from safelane.planners.base import ExpertPlanner as Expert
    from safelane.sim.step import ClosedLoop

    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    batch = paper_scenarios("CV_all", 3, 5.0, 70, np.random.default_rng(0), first_id=300)
    sim = ClosedLoop(batch, 0, Params(), SimConfig(), Expert())
    sim.b.v[5, 2] = np.inf  # past the batch's validation: what a bug in a behaviour would leave
    with pytest.raises(FloatingPointError, match=r"scenario\(s\) \[305\]"):
        _fused.run(sim, 100)
