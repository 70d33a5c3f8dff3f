"""The realistic preset's braking limits: the others brake up to ``a_o_d`` ≥ 9 m/s² (real cars), the ego commits
to ``a_x_d`` = 6 in its evasion — and with ``L(N+1)`` braking at 9 m/s² the shield keeps every gap (0 collisions,
0 ``p_m`` violations) under every variant."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from safelane import Params
from safelane.safety import leader_chain
from safelane.sim import simulate
from safelane.sim.preset import load_preset

VARIANTS = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")


def test_the_realistic_preset_lets_the_others_brake_harder_than_the_ego_commits_to():
    prm = load_preset("realistic").params
    assert prm.a_o_d is not None and prm.others_decel >= 9.0 > prm.a_x_d


@pytest.mark.parametrize("planner", VARIANTS)
def test_last_leader_braking_at_nine_keeps_every_gap_in_the_realistic_world(planner):
    """150 scenarios with a non-connected L1 (N = 0: L1 is L(N+1)) and 150 with a chain of 5, L(N+1) braking at
    9 m/s² > a_x_d, L0 braking at a_o_d, sensing error and delay: from every start the shield certifies
    (``initial_safe``: the guarantee's premise) nothing collides and no gap breaks its margin. Starting under the
    most conservative assumptions (L1 and L0 able to brake at 9.5, F aggressive) about half of the starts cannot be
    certified; those are outside the guarantee."""
    tables = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for n_leaders in (0, 5):
            tables.append(simulate(planner, n_leaders=n_leaders, decel=9.0, samples=150, seed=11,
                                   preset="realistic").table)  # fmt: skip
    for tb in tables:
        assert len(tb) == 150 and (tb["decel"] == 9.0).all()
        inside = tb[tb["initial_safe"].astype(bool)]
        assert len(inside) >= 0.3 * len(tb), (planner, len(inside))
        for col in ("collision", "safety_violation", "own_lane_collision", "own_lane_violation"):
            assert not inside[col].any(), (planner, col, int(inside[col].sum()))


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "hard"])
def test_params_refuse_an_others_maximum_that_is_not_a_finite_non_negative_number(bad):
    with pytest.raises(ValueError, match="a_o_d"):
        Params(a_o_d=bad)


def test_the_others_maximum_defaults_to_the_egos_and_bounds_the_chain():
    assert Params().a_o_d is None and Params().others_decel == Params().a_x_d
    prm = Params(a_x_d=6.0, a_o_d=9.5)
    chain = leader_chain([[0.0]], [[20.0]], np.zeros((1, 0)), prm)  # N = 0: L1 is not connected
    assert chain.l1_decel[0] == 9.5
    with pytest.raises(ValueError, match=r"a_o_d=9\.5"):
        leader_chain([[0.0, 30.0]], [[20.0, 20.0]], [[9.6]], prm)
