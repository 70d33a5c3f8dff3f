"""Issue 12: the paper's completion rule, the slow assessment, the structure-aware loss and the two modes."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from safelane import Params
from safelane.experiments.modes import SAFE_MODE, safe_preset
from safelane.experiments.paper_data import table1_long
from safelane.experiments.structure import FOLLOWER_RATIO, paper_effects, structure_metrics, to_preset
from safelane.planners.base import ExpertPlanner, Observation
from safelane.shield import ShieldConfig, Situation
from safelane.shield.policies import ASSESSMENTS, COMPLETION_RULES
from safelane.sim import SimConfig, simulate
from safelane.sim.preset import load_preset

PRM = Params()


def _yielding_follower(n: int = 3, seconds: float = 4.0, start_s: float = 0.0):
    """Situations of ``n`` scenarios whose F slows at 1 m/s² from ``start_s`` on (collaborative evidence), each
    scenario with another start gap (so their random draws differ)."""
    for k in range(round(seconds / PRM.dt)):
        t = k * PRM.dt
        v = 30.0 - max(t - start_s, 0.0)
        yield Situation.from_arrays(t=t, ego=(np.zeros(n), 0.0, 30.0, 0.0), follower=(-20.0 - np.arange(n), v),
                                    leaders=(np.full((n, 1), 25.0), np.full((n, 1), 30.0)), n_connected=0,
                                    params=PRM)  # fmt: skip


def _released_at(cfg: ShieldConfig, n: int = 3) -> np.ndarray:
    model = ASSESSMENTS[cfg.assessment]
    state, first = model.start(n, cfg), np.full(n, np.nan)
    for sit in _yielding_follower(n):
        state = model.update(state, sit, PRM.dt, cfg)
        first = np.where(np.isnan(first) & ~model.aggressive(state, sit), sit.t, first)
    return first


def test_slow_assessment_releases_later_and_misses_on_the_safe_side():
    observed = _released_at(ShieldConfig(assessment="observed", assess_window=5, assess_threshold=0.2))
    slow = _released_at(ShieldConfig(assessment="slow", assess_window=5, assess_threshold=0.2, assess_delay_s=1.0))
    assert np.isfinite(observed).all() and np.isfinite(slow).all()
    delay = slow - observed
    assert ((delay >= 0.5 - 1e-9) & (delay <= 1.5 + PRM.dt + 1e-9)).all()  # uniform on [0.5, 1.5] x 1 s
    never = _released_at(ShieldConfig(assessment="slow", assess_window=5, assess_threshold=0.2, assess_miss=1.0))
    assert np.isnan(never).all()  # a missed collaborative F stays "aggressive": conservative


def test_slow_assessment_draws_do_not_depend_on_the_batch():
    cfg = ShieldConfig(assessment="slow", assess_window=5, assess_threshold=0.2, assess_delay_s=2.0)
    assert np.array_equal(_released_at(cfg, 3)[:2], _released_at(cfg, 2))


def test_paper_completion_rule_is_registered_and_keeps_the_evasion_check():
    rule = COMPLETION_RULES["paper_evasion"]
    assert rule.needs_evasion and rule(*(np.zeros(4) for _ in range(7)), PRM).all()
    assert SimConfig(completion="paper_evasion").shield.completion == "paper_evasion"
    with pytest.raises(ValueError):
        SimConfig(completion="none")


def test_the_paper_rule_completes_at_least_as_often_as_the_commit_guard():
    """The commit guard is the stricter test at the crossing step: the paper's rule can only complete more."""
    common = {"leader_rule": "reactive", "monitor": False, "horizon_s": 8.0}
    guard = simulate("CV_all", 1, 4.0, 60, 0, config=SimConfig(**common)).table
    paper = simulate("CV_all", 1, 4.0, 60, 0, config=SimConfig(completion="paper_evasion", **common)).table
    assert paper["success"].mean() >= guard["success"].mean()


def test_brake_comfort_caps_the_nominal_braking():
    obs = Observation(p_x=np.zeros(2), p_y=np.zeros(2), v_x=np.full(2, 30.0), v_y=np.zeros(2), p_x_l=np.full(2, 8.0),
                      v_x_l=np.full(2, 20.0), p_x_f=np.full(2, -20.0), v_x_f=np.full(2, 30.0),
                      l1_plan=np.zeros((2, 1)), l1_connected=np.ones(2, bool), f_connected=np.ones(2, bool),
                      completed=np.zeros(2, bool))  # fmt: skip
    free, _ = ExpertPlanner(k_v=0.8)(obs, PRM)
    capped, _ = ExpertPlanner(k_v=0.8, brake_comfort=2.0)(obs, PRM)
    assert free.min() < -2.0 and np.allclose(capped, -2.0)


def test_structure_metrics_of_the_paper_itself():
    fit = pd.DataFrame(table1_long()).assign(success_rate=lambda f: f["paper_success"])
    m = structure_metrics(fit)
    assert m["mae"] == 0.0 and m["adj_err"] == 0.0 and m["claim_penalty"] == 0.0
    assert m["follower_effect"] == pytest.approx(0.325) and m["chain_effect"] == pytest.approx(0.02)
    assert paper_effects()["follower_effect"] >= FOLLOWER_RATIO * paper_effects()["chain_effect"]
    # Our old fit's structure (CV_follow = CV_none everywhere, the chain effect large) is penalised.
    inverted = fit.copy()
    inverted.loc[inverted["planner"] == "CV_none", "success_rate"] = inverted.loc[
        inverted["planner"] == "CV_follow", "success_rate"].to_numpy()  # fmt: skip
    assert structure_metrics(inverted)["follower_effect"] == 0.0


def test_the_two_modes():
    paper = load_preset("paper")
    safe = safe_preset(paper)
    assert safe.sim.model_copy(update=SAFE_MODE) == safe.sim != paper.sim  # every rule of the safe mode applied
    rules = (safe.sim.shield.completion, safe.sim.leader_rule, safe.sim.shield.monitor)
    assert rules == ("commit_guard", "worst_case", True)
    assert safe.params == paper.params and safe.planner == paper.planner
    shipped = load_preset("safe")
    assert shipped.sim.model_copy(update=SAFE_MODE) == shipped.sim and shipped.params == paper.params
    assert shipped.planner == paper.planner and shipped.network == paper.network == "mlp_paper"
    assert shipped.sim == safe.sim  # every other setting is the paper preset's
    assert paper.sim.shield.completion == "paper_evasion" and paper.sim.leader_rule == "reactive"
    point = {"a_x_d": 7.0, "k_p": 0.4, "assess_delay_s": 2.0, "assess_window": 6.4}
    preset = to_preset(point)
    assert preset.params.a_x_d == 7.0 and preset.planner["k_p"] == 0.4 and preset.sim.shield.assess_window == 6
    assert preset.sim.shield.assess_delay_s == 2.0 and preset.sim.shield.completion == "paper_evasion"


def test_under_the_body_across_rule_an_ego_past_the_centre_line_can_still_turn_back():
    """``paper_body_across``: crossing the centre line is not final — some egos cross it and turn back — and every
    completion happens with the whole car across (the trace's first completed row)."""
    preset = load_preset("paper")
    cfg = preset.sim.model_copy(update={"completion": "paper_body_across", "horizon_s": 6.0})
    run = simulate("CV_all", 1, 3.0, 200, 0, params=preset.params, config=cfg, nominal=preset.expert(), trace=True)
    trace, table = run.trace, run.table
    level = preset.params.y_boundary + 0.5 * preset.params.vehicle_width
    peak = trace.groupby("scenario_id")["ego_y"].max()
    done = table.set_index("scenario_id")["completed"]
    turned_back = (peak > preset.params.y_boundary) & ~done.reindex(peak.index)
    assert turned_back.sum() >= 5
    first = trace[trace["completed"]].groupby("scenario_id")["ego_y"].first()
    assert len(first) >= 5 and (first >= level - 1e-9).all()
    assert not table["collision"].any()


def test_structure_loss_weights_and_the_completion_rule_of_a_search_point():
    fit = pd.DataFrame(table1_long()).assign(success_rate=lambda f: f["paper_success"])
    chained = fit.copy()
    chained.loc[chained["planner"] == "CV_all", "success_rate"] += 0.05  # a chain effect the paper does not have
    base, heavy = structure_metrics(chained), structure_metrics(chained, w_claim=3.0)
    assert base["claim_penalty"] > 0.0
    assert heavy["loss"] - base["loss"] == pytest.approx(2.0 * base["claim_penalty"])
    assert to_preset({"k_v": 1.0}).sim.shield.completion == "paper_evasion"
    assert to_preset({"k_v": 1.0}, completion="paper_body_across").sim.shield.completion == "paper_body_across"
