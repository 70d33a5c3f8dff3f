"""Issue 31: a Situation whose lanes are out of order is named where it is built (field, row, positions: a warning,
or an error with ``geometry="raise"``) and answered conservatively by the shield; the geometry that is possible but
outside the lane change's picture (L1 beside or behind the ego, F ahead of it) is the documented conservative
fallback; ``safelane check`` refuses a lateral position outside the two lanes and vehicles out of order."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

from safelane import Params
from safelane.cli import app
from safelane.errors import InputError
from safelane.shield import (
    ABORT,
    HESITATE,
    PROCEED,
    GeometryWarning,  # exported where users filter it
    Shield,
    Situation,
)

PRM = Params()


def _sit(follower=(-20.0, 30.0), leaders=([20.0, 40.0, 60.0], [30.0] * 3), n=2, ego_y=0.0, ego_vy=0.0, **kw):
    return Situation.from_arrays(t=0.0, ego=(0.0, ego_y, 30.0, ego_vy), follower=follower, leaders=leaders,
                                 n_connected=n, params=PRM, **kw)  # fmt: skip


def test_leaders_out_of_order_are_named_with_the_field_and_positions():
    with pytest.warns(GeometryWarning, match=r"Situation.chain_x: L2 at 20 m is behind L1 at 60 m \(row 0\)"):
        _sit(leaders=([60.0, 20.0, 80.0], [30.0] * 3))
    with pytest.raises(InputError, match=r"Situation.chain_x: L3 at 30 m is behind L2 at 40 m \(row 1\)"):
        _sit(leaders=([[20.0, 40.0, 60.0], [20.0, 40.0, 30.0]], [[30.0] * 3] * 2), geometry="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _sit(leaders=([60.0, 20.0, 80.0], [30.0] * 3), geometry="ignore")
    with pytest.raises(InputError, match="geometry must be one of warn, raise, ignore; got 'strict'"):
        _sit(geometry="strict")


def test_a_valid_situation_says_nothing():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sit = _sit(own_leaders=([30.0, np.inf], [30.0, 30.0]), geometry="raise")
    assert sit.order_problems() == []


def test_slots_beyond_the_last_known_leader_are_not_checked():
    # N = 1: L(N+1) = L2; the third slot is not read by the analysis (padding, or a dropped vehicle).
    assert _sit(leaders=([20.0, 40.0, 0.0], [30.0] * 3), n=1, geometry="raise").order_problems() == []


def test_equal_positions_are_an_overlap_not_an_order_break():
    # A crash ahead: the chain analysis calls the link unsafe.
    assert _sit(leaders=([20.0, 20.0, 60.0], [30.0] * 3), geometry="raise").order_problems() == []


def test_follower_ahead_of_l1_is_named():
    with pytest.raises(InputError, match=r"Situation.f_x: F at 30 m is ahead of L1 at 20 m \(row 0\)"):
        _sit(follower=(30.0, 30.0), leaders=([20.0], [30.0]), n=0, geometry="raise")
    with pytest.warns(GeometryWarning, match=r"Situation.f_x: F at 30 m is ahead of L1 at 20 m"):
        _sit(follower=(30.0, 30.0), leaders=([20.0], [30.0]), n=0)


def test_own_lane_leaders_out_of_order_are_named():
    with pytest.raises(InputError, match=r"Situation.own_x: own-lane leader 1 at 10 m is behind leader 0 at 30 m"):
        _sit(own_leaders=([30.0, 10.0], [30.0, 30.0]), geometry="raise")


def test_leaders_out_of_order_make_l1s_worst_case_the_hardest_braking():
    """The conservative answer to a chain out of order: the link is unsafe, L1 may brake at a_x_d."""
    ordered = _sit(n=2)
    with pytest.warns(GeometryWarning):
        reversed_ = _sit(leaders=([60.0, 40.0, 20.0], [30.0] * 3), n=2)
    decisions = []
    for sit in (ordered, reversed_):
        shield = Shield(PRM, variant="CV_all")
        shield.reset(sit)
        decisions.append(shield.step(sit, (0.0, 0.0)))
    assert decisions[0].l1_decel[0] < PRM.a_x_d
    assert decisions[1].l1_decel[0] == PRM.a_x_d


@pytest.mark.parametrize(
    ("follower", "leaders"),
    [
        ((-20.0, 30.0), ([-5.0], [30.0])),  # L1 behind the ego (the ego overtook it in its own lane)
        ((-20.0, 30.0), ([0.0], [30.0])),  # L1 beside the ego
        ((5.0, 30.0), ([30.0], [30.0])),  # F ahead of the ego
        ((-3.0, 30.0), ([30.0], [30.0])),  # F closer than p_m behind
    ],
)
def test_l1_behind_or_f_ahead_of_the_ego_is_a_conservative_fallback(follower, leaders):
    """Accepted (possible, and extrapolated V2X states produce it), never a lane change: at the edge of the own lane
    moving out, every proposal is refused; inside the own lane, moving within it stays allowed."""
    edge = _sit(follower=follower, leaders=leaders, n=0, ego_y=PRM.y_safe, ego_vy=0.5)
    for a_y in (PRM.a_y_m, 0.0, -PRM.a_y_m):
        shield = Shield(PRM)
        shield.reset(edge)
        decision = shield.step(edge, (0.0, a_y))
        assert int(decision.behaviour[0]) in (HESITATE, ABORT)
        assert not decision.completing[0]
    inside = _sit(follower=follower, leaders=leaders, n=0)
    shield = Shield(PRM)
    shield.reset(inside)
    assert int(shield.step(inside, (0.0, 0.5)).behaviour[0]) == PROCEED


def test_the_same_edge_state_with_the_others_in_place_proceeds():
    edge = _sit(follower=(-30.0, 30.0), leaders=([40.0], [30.0]), n=0, ego_y=PRM.y_safe, ego_vy=0.5,
                f_connected=True, f_collaborative=True)  # fmt: skip
    shield = Shield(PRM)
    shield.reset(edge)
    assert int(shield.step(edge, (0.0, 0.5)).behaviour[0]) == PROCEED


def _cli(*args: str):
    return CliRunner().invoke(app, ["check", *args])


@pytest.mark.parametrize("ego_py", ["50", "-3", "5.3"])
def test_check_refuses_a_lateral_position_outside_the_two_lanes(ego_py):
    result = _cli("--ego-py", ego_py)
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert "--ego-py" in text and "outside the two lanes" in text and "[-1.75, 5.25] m" in text
    assert "FOLLOWER_TOO_CLOSE" not in result.output


def test_check_accepts_both_lane_edges_and_refuses_swapped_vehicles():
    assert _cli("--ego-py", "-1.75").exit_code == 0 and _cli("--ego-py", "5.25").exit_code == 0
    swapped = _cli("--f-p", "30")
    assert swapped.exit_code == 2 and "--f-p" in swapped.output and "ahead of L1" in " ".join(swapped.output.split())
    chain = _cli("--chain-p", "10", "--chain-v", "30")
    text = " ".join(chain.output.split())
    assert chain.exit_code == 2 and "--chain-p" in text and "L2 at 10 m is behind L1 at 20 m" in text


# -- the fast check of the value rules (Situation._values_pass) against the rules one by one
_VALUE_FIELDS = ("ego_x", "ego_y", "ego_vx", "ego_vy", "f_x", "f_v", "chain_x", "chain_v", "chain_promise",
                 "n_connected")  # fmt: skip
_SPEEDS = ("ego_vx", "f_v", "chain_v")


def _batch(b=6, m=4):
    rng = np.random.default_rng(b * 10 + m)
    lx = np.sort(rng.uniform(10.0, 90.0, (b, m)), axis=1)
    return Situation.from_arrays(
        t=0.0, ego=(rng.uniform(-5, 5, b), rng.uniform(0, 3, b), rng.uniform(0, 30, b), rng.uniform(-1, 1, b)),
        follower=(rng.uniform(-60, -10, b), rng.uniform(0, 30, b)), leaders=(lx, rng.uniform(0, 30, (b, m))),
        n_connected=rng.integers(0, m, b), promise_decel=rng.uniform(0, PRM.a_x_d, (b, m - 1)), params=PRM,
    )  # fmt: skip


def _bad_values(name):
    """Values each field must refuse (every field: NaN and ±inf; speeds: below 0; promises: outside [0, a_x_d];
    N: outside [0, M − 1])."""
    if name == "n_connected":
        return [-1, 4]
    out = [np.nan, np.inf, -np.inf]
    if name in _SPEEDS:
        out.append(-1e-9)
    if name == "chain_promise":
        out += [-1e-9, PRM.a_x_d + 1e-9]
    return out


@pytest.mark.parametrize("name", _VALUE_FIELDS)
def test_the_fast_check_fails_exactly_where_a_rule_refuses_and_the_rule_names_the_field(name):
    ok = _batch()
    assert ok._values_pass(PRM, 4)
    edge = {"n_connected": 3, "chain_promise": PRM.a_x_d}.get(name, 0.0)  # the limits themselves are accepted
    for value in [*_bad_values(name), edge]:
        for row in (0, 5):
            arr = getattr(ok, name).copy()
            arr[row] = value
            s = dataclasses.replace(ok, **{name: arr})
            accepted = value is edge
            assert s._values_pass(PRM, 4) == accepted, (name, value, row)
            if accepted:
                s.validate(PRM)
            else:
                with pytest.raises(ValueError, match=f"Situation.{name}"):
                    s.validate(PRM)
