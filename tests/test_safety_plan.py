"""The :class:`~safelane.safety.EvasionPlan` container (``safety/plan.py``): the defaults of plans without an own-lane
leader ``L0``, the fields :func:`~safelane.safety.plan.plan_from_core` fills from an own-lane check, the row
operations the shield uses (``where``, ``take``, :func:`~safelane.safety.plan.set_rows`), and the planned motion of a
plan that *continues* after ``t_y_f`` (own-lane plans) against independent time stepping (``tests/reference.py``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from reference import _profile, _simulate
from safelane import Params
from safelane.safety import EvasionPlan, Reason, plan_evasion
from safelane.safety._backend import ARRAY, FEASIBILITY_TOL_M
from safelane.safety.own_lane import own_lane_core
from safelane.safety.plan import plan_from_core, set_rows

PRM = Params()
OWN_MARGIN = PRM.p_m + 0.5 * FEASIBILITY_TOL_M  # the shield's margin to L0 (shield.decide.own_margin)
OWN_FIELDS = ("own_p", "own_v", "own_decel", "follows_own", "continues", "min_gap_own")
STATE_KEYS = ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "f_p", "f_v")


def _states(n: int, seed: int) -> dict:
    """Mid-lane-change states with ``L1`` and ``F`` in the target lane and ``L0`` ahead in the own lane."""
    rng = np.random.default_rng(seed)
    u = rng.uniform
    ego_px = u(-5.0, 5.0, n)
    return dict(
        ego_px=ego_px, ego_py=u(PRM.y_safe, 2.6, n), ego_vx=u(5.0, 30.0, n), ego_vy=u(-0.5, 1.0, n),
        l1_p=ego_px + PRM.p_m + u(0.0, 40.0, n), l1_v=u(0.0, 30.0, n), l1_decel=u(0.0, PRM.a_x_d, n),
        f_p=ego_px - PRM.p_m - u(2.0, 60.0, n), f_v=u(0.0, 30.0, n), follower_aggressive=rng.random(n) < 0.3,
        l0_p=ego_px + OWN_MARGIN + u(0.0, 40.0, n), l0_v=u(0.0, 30.0, n), l0_decel=u(0.0, PRM.a_x_d, n),
    )  # fmt: skip


def _plain_plan(s: dict) -> EvasionPlan:
    return plan_evasion(**{k: s[k] for k in (*STATE_KEYS, "follower_aggressive")}, params=PRM)


def _own_plan(s: dict, **chain_unsafe):
    """An own-lane plan built the way the shield builds it (``shield.realworld.own_plan``: no ``chain_unsafe``);
    also its verdicts and parts."""
    args = tuple(s[k] for k in (*STATE_KEYS, "follower_aggressive"))
    own = (s["l0_p"], s["l0_v"], s["l0_decel"])
    exists, parts = own_lane_core(*args, *own, PRM.p_m, PRM.p_m, OWN_MARGIN, PRM)
    n = s["ego_px"].shape
    plan = plan_from_core(ARRAY, n, (*args[:9], PRM.p_m, PRM.p_m), exists, parts, PRM.p_m, PRM.p_m, PRM,
                          own=(*own, OWN_MARGIN), **chain_unsafe)  # fmt: skip
    return plan, exists, parts


@pytest.fixture(scope="module")
def own():
    s = _states(400, 1)
    plan, exists, parts = _own_plan(s)
    # Both members of the family occur, and both verdicts.
    assert 0 < parts["follows_own"].sum() < 400 and 0 < exists.sum() < 400
    return s, plan, exists, parts


def _fields(plan: EvasionPlan):
    return [f.name for f in dataclasses.fields(plan) if f.name != "params"]


# --- plans without L0 -------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [None, 4])
def test_plans_without_l0_carry_the_papers_defaults(n):
    s = _states(4, 2)
    plan = _plain_plan({k: (v[0].item() if n is None else v) for k, v in s.items()})
    shape = () if n is None else (n,)
    expected = dict(own_p=np.inf, own_v=0.0, own_decel=0.0, follows_own=False, continues=False, min_gap_own=np.inf)
    for name, value in expected.items():
        arr = getattr(plan, name)
        assert isinstance(arr, np.ndarray) and arr.shape == shape, name
        assert arr.dtype == (np.bool_ if isinstance(value, bool) else np.float64), name
        assert np.all(arr == value), name
    assert plan.lead == (plan.l1_p, plan.l1_v, plan.l1_decel)


# --- plan_from_core with L0 ----------------------------------------------------------------------------------------


def test_an_own_lane_plan_records_l0_and_continues(own):
    s, plan, exists, parts = own
    np.testing.assert_array_equal(plan.own_p, s["l0_p"])
    np.testing.assert_array_equal(plan.own_v, s["l0_v"])
    np.testing.assert_array_equal(plan.own_decel, s["l0_decel"])
    np.testing.assert_array_equal(plan.follows_own, parts["follows_own"])
    assert plan.continues.dtype == np.bool_ and plan.continues.all()
    assert plan.follows_own.dtype == np.bool_
    np.testing.assert_array_equal(plan.min_gap_own, parts["own_gap"] + OWN_MARGIN)
    # The fields a plan without L0 has too, from the same parts.
    np.testing.assert_array_equal(plan.feasible, exists)
    np.testing.assert_array_equal(plan.t_x1, parts["t_x1"])
    np.testing.assert_array_equal(plan.t_x2, np.minimum(parts["t_brake_end"], parts["t_y_f"]))
    np.testing.assert_array_equal(plan.min_gap_leader, parts["lead_gap"] + PRM.p_m)
    np.testing.assert_array_equal(plan.min_gap_follower, parts["follow_gap"] + PRM.p_m)
    for key in ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel"):
        np.testing.assert_array_equal(getattr(plan, key), s[key])
    for key in ("t_y_f", "t_y_switch", "v_switch", "t_brake_end", "y_acc_1", "y_acc_2", "t_y_end"):
        np.testing.assert_array_equal(getattr(plan, key), parts[key])
    np.testing.assert_array_equal(plan.follows_leader, parts["follows_leader"])
    # The reason bits: the leader constraints first, the follower only where they hold.
    assert not (plan.reason & Reason.CHAIN_UNSAFE).any()  # not flagged unless said so
    lead_bad = (plan.reason & Reason.LEADER_INFEASIBLE) != 0
    follow_bad = (plan.reason & Reason.FOLLOWER_TOO_CLOSE) != 0
    np.testing.assert_array_equal(lead_bad, ~parts["lead_ok"])
    np.testing.assert_array_equal(follow_bad, parts["lead_ok"] & ~parts["follow_ok"])
    assert lead_bad.any() and follow_bad.any() and (plan.reason == 0).any()
    # The profile follows L0 where it says so, L1 elsewhere.
    lead = plan.lead
    own_rows = plan.follows_own
    for got, l0, l1 in zip(lead, (s["l0_p"], s["l0_v"], s["l0_decel"]), (s["l1_p"], s["l1_v"], s["l1_decel"]),
                           strict=True):  # fmt: skip
        np.testing.assert_array_equal(got, np.where(own_rows, l0, l1))


def test_the_chain_flag_reaches_an_own_lane_plan():
    s = _states(6, 3)
    flags = np.array([True, False, True, False, False, True])
    plan, *_ = _own_plan(s, chain_unsafe=flags)
    np.testing.assert_array_equal((plan.reason & Reason.CHAIN_UNSAFE) != 0, flags)
    assert plan.reason.dtype == np.uint8


# --- the planned motion of a continuing plan -------------------------------------------------------------------------


def _reference_motion(plan: EvasionPlan, t):
    """Position and speed at ``t`` of the accelerate (``[0, t_x1]``) → brake → follow-the-lead profile, time-stepped
    (``tests/reference.py``), with the lead ``plan.lead``: the engine's switch time, nothing else of its profile."""
    p1, v1, a1 = plan.lead
    prof = _profile(plan.t_x1, plan.ego_vx, v1, a1, PRM)
    _, _, (pe, ve, _), _ = _simulate(prof, plan.ego_px, plan.ego_vx, p1, v1, a1, t, PRM)
    return pe[:, -1], ve[:, -1]


@pytest.mark.parametrize("factor", [0.3, 1.0, 1.7, 4.0])
def test_a_continuing_plan_keeps_its_profile_after_t_y_f(own, factor):
    _, plan, *_ = own
    rows = np.flatnonzero(plan.t_y_f > 0.5)
    sub = plan.take(rows)
    t = sub.t_y_f * factor + 0.05
    px, _, vx, _ = sub.state(t)
    ref_px, ref_vx = _reference_motion(sub, t)
    np.testing.assert_allclose(px, ref_px, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(vx, ref_vx, rtol=1e-9, atol=1e-6)


def test_a_plan_that_does_not_continue_holds_its_speed_after_t_y_f(own):
    s, own_plan, *_ = own
    plan = _plain_plan(s)
    rows = np.flatnonzero(plan.t_y_f > 0.5)
    sub = plan.take(rows)
    at_T = _reference_motion(sub, sub.t_y_f)
    for extra in (0.0, 0.5, 3.0):
        px, _, vx, _ = sub.state(sub.t_y_f + extra)
        np.testing.assert_allclose(vx, at_T[1], rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(px, at_T[0] + at_T[1] * extra, rtol=1e-9, atol=1e-6)
    # The same rows planned with L0 differ after t_y_f where the profile is still braking then.
    later = own_plan.take(rows).state(sub.t_y_f + 3.0)[2]
    assert np.any(np.abs(later - sub.state(sub.t_y_f + 3.0)[2]) > 0.1)


# --- row operations --------------------------------------------------------------------------------------------------


def test_where_chooses_every_field_row_by_row(own):
    s, own_plan, *_ = own
    plain = _plain_plan(s)
    mask = np.arange(400) % 3 == 0
    mixed = own_plan.where(mask, plain)
    assert mixed.params is own_plan.params
    for name in _fields(mixed):
        np.testing.assert_array_equal(getattr(mixed, name), np.where(mask, getattr(own_plan, name),
                                                                      getattr(plain, name)), err_msg=name)  # fmt: skip
    other = plain.where(mask, own_plan)
    for name in OWN_FIELDS:
        expected = np.where(mask, getattr(plain, name), getattr(own_plan, name))
        np.testing.assert_array_equal(getattr(other, name), expected, err_msg=name)
    t = np.linspace(0.0, 6.0, 400)
    for a, b, c in zip(mixed.state(t), own_plan.state(t), plain.state(t), strict=True):
        np.testing.assert_array_equal(a, np.where(mask, b, c))


def test_take_selects_rows_of_every_field(own):
    _, plan, *_ = own
    idx = np.array([5, 0, 399, 5])
    rows = plan.take(idx)
    assert rows.params is plan.params
    for name in _fields(plan):
        np.testing.assert_array_equal(getattr(rows, name), getattr(plan, name)[idx], err_msg=name)
    one = plan.take(7)
    assert one.feasible.shape == ()
    assert one.state(1.0)[0] == plan.state(1.0)[0][7]


def test_set_rows_replaces_the_rows_of_each_piece_in_order(own):
    s, own_plan, *_ = own
    base = _plain_plan(s)
    before = {name: getattr(base, name).copy() for name in _fields(base)}
    first, second = np.arange(0, 40), np.arange(30, 60)
    out = set_rows(base, [(first, own_plan.take(first)), (np.array([], dtype=int), base.take(np.arange(0))),
                          (second, own_plan.take(second))])  # fmt: skip
    assert out.params is base.params
    replaced = np.zeros(400, bool)
    replaced[:60] = True
    for name in _fields(base):
        np.testing.assert_array_equal(getattr(out, name), np.where(replaced, getattr(own_plan, name),
                                                                    getattr(base, name)), err_msg=name)  # fmt: skip
        np.testing.assert_array_equal(getattr(base, name), before[name], err_msg=name)  # the base is not modified
    # Later pieces win where pieces overlap.
    shifted = own_plan.take(np.arange(30, 60)).where(np.ones(30, bool), base.take(np.arange(30, 60)))
    out2 = set_rows(base, [(np.arange(30, 60), base.take(np.arange(0, 30))), (np.arange(30, 60), shifted)])
    np.testing.assert_array_equal(out2.t_x1[30:60], own_plan.t_x1[30:60])
    assert out.state(2.0)[0].shape == (400,)


def test_set_rows_without_rows_to_replace_is_the_plan_itself():
    plan = _plain_plan(_states(5, 4))
    assert set_rows(plan, []) is plan
    assert set_rows(plan, [(np.array([], dtype=int), plan.take(np.arange(0)))]) is plan
