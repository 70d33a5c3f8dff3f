"""Bad input to every public safety function, and to ``Params``, raises ``ValueError`` naming the field.

Each numeric argument is tried with NaN, ±inf and a non-numeric string, on both the scalar path (Python floats)
and the batched path (the bad value at one index of an array); physical ranges (speeds >= 0, decelerations in
``[0, a_x_d]``, times >= 0), boolean flags, chain lengths and batch shapes are checked too.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import scenarios
from safelane import Params, safety
from safelane.safety import (
    evasion_exists,
    follower_position,
    lateral_evasion_time,
    leader_chain,
    leader_position,
    longitudinal_evasion,
    plan_evasion,
    worst_case_leader_decel,
)

PARAMS = Params()
NON_FINITE = [np.nan, np.inf, -np.inf]
NOT_NUMBERS = ["abc", "1.5", None, 1 + 2j, [[1.0, 2.0], [3.0]]]
NOT_BOOLEANS = [np.nan, 2, -1, 0.5, "yes", None]


def _raises_naming(name: str):
    return pytest.raises(ValueError, match=rf"\b{re.escape(name)}\b")


def _batched(value, bad, index=2, size=4):
    """A batch of ``value`` with ``bad`` at ``index``."""
    arr = np.full(size, value, dtype=np.asarray(bad).dtype if isinstance(bad, (bool, np.bool_)) else np.float64)
    arr[index] = bad
    return arr


# --- the functions under test, each as (name, call(**kwargs), valid kwargs, argument kinds) ----------------------


def _evasion_kwargs() -> dict:
    return scenarios.open_gap_collaborative_follower()


def _lon_kwargs() -> dict:
    s = _evasion_kwargs()
    keys = ("ego_px", "ego_vx", "l1_p", "l1_v", "l1_decel")
    return {**{k: s[k] for k in keys}, "t_y_f": 2.0}


FUNCTIONS = {
    "evasion_exists": (lambda **kw: evasion_exists(**kw, params=PARAMS), _evasion_kwargs),
    "plan_evasion": (lambda **kw: plan_evasion(**kw, params=PARAMS), _evasion_kwargs),
    "lateral_evasion_time": (lambda **kw: lateral_evasion_time(**kw, params=PARAMS), lambda: dict(p_y=1.5, v_y=0.3)),
    "longitudinal_evasion": (lambda **kw: longitudinal_evasion(**kw, params=PARAMS), _lon_kwargs),
    "follower_position": (
        lambda **kw: follower_position(**kw, params=PARAMS),
        lambda: dict(p=-20.0, v=25.0, aggressive=True, t=1.0),
    ),
    "leader_position": (
        lambda **kw: leader_position(**kw, params=PARAMS),
        lambda: dict(p=40.0, v=25.0, decel=8.0, t=1.0),
    ),
}

NUMERIC_ARGS = {
    "evasion_exists": ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "f_p", "f_v"),
    "plan_evasion": ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "f_p", "f_v"),
    "lateral_evasion_time": ("p_y", "v_y"),
    "longitudinal_evasion": ("ego_px", "ego_vx", "l1_p", "l1_v", "l1_decel", "t_y_f"),
    "follower_position": ("p", "v", "t"),
    "leader_position": ("p", "v", "decel", "t"),
}
NONNEG_ARGS = {
    "evasion_exists": ("ego_vx", "l1_v", "l1_decel", "f_v"),
    "plan_evasion": ("ego_vx", "l1_v", "l1_decel", "f_v"),
    "longitudinal_evasion": ("ego_vx", "l1_v", "l1_decel", "t_y_f"),
    "follower_position": ("v", "t"),
    "leader_position": ("v", "decel", "t"),
}
DECEL_ARGS = {"evasion_exists": "l1_decel", "plan_evasion": "l1_decel", "longitudinal_evasion": "l1_decel",
              "leader_position": "decel"}  # fmt: skip
BOOL_ARGS = {
    "evasion_exists": ("follower_aggressive", "leader_human", "follower_human"),
    "plan_evasion": ("follower_aggressive", "leader_human", "follower_human", "chain_unsafe"),
    "follower_position": ("aggressive",),
}


def _cases(table):
    return [(fn, arg) for fn, args in table.items() for arg in ((args,) if isinstance(args, str) else args)]


@pytest.mark.parametrize(("fn", "arg"), _cases(NUMERIC_ARGS))
@pytest.mark.parametrize("bad", NON_FINITE, ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("batched", [False, True], ids=["scalar", "batched"])
def test_non_finite_value_is_named(fn, arg, bad, batched):
    call, valid = FUNCTIONS[fn]
    kw = valid()
    kw[arg] = _batched(kw[arg], bad) if batched else bad
    with _raises_naming(arg) as info:
        call(**kw)
    if batched:
        assert "index (2,)" in str(info.value)


@pytest.mark.parametrize(("fn", "arg"), _cases(NUMERIC_ARGS))
@pytest.mark.parametrize("bad", NOT_NUMBERS, ids=["word", "numeric-string", "none", "complex", "ragged"])
def test_non_numeric_value_is_named(fn, arg, bad):
    call, valid = FUNCTIONS[fn]
    with _raises_naming(arg):
        call(**{**valid(), arg: bad})


@pytest.mark.parametrize(("fn", "arg"), _cases(NONNEG_ARGS))
@pytest.mark.parametrize("batched", [False, True], ids=["scalar", "batched"])
def test_negative_speed_decel_or_time_is_named(fn, arg, batched):
    call, valid = FUNCTIONS[fn]
    kw = valid()
    kw[arg] = _batched(kw[arg], -0.5) if batched else -0.5
    with _raises_naming(arg):
        call(**kw)


@pytest.mark.parametrize(("fn", "arg"), _cases(DECEL_ARGS))
@pytest.mark.parametrize("batched", [False, True], ids=["scalar", "batched"])
def test_decel_above_mechanical_limit_is_named(fn, arg, batched):
    call, valid = FUNCTIONS[fn]
    too_hard = PARAMS.a_x_d + 0.1
    kw = valid()
    kw[arg] = _batched(kw[arg], too_hard) if batched else too_hard
    with _raises_naming(arg):
        call(**kw)


@pytest.mark.parametrize(("fn", "arg"), _cases(BOOL_ARGS))
@pytest.mark.parametrize("bad", NOT_BOOLEANS, ids=["nan", "two", "minus-one", "half", "word", "none"])
def test_non_boolean_flag_is_named(fn, arg, bad):
    call, valid = FUNCTIONS[fn]
    with _raises_naming(arg):
        call(**{**valid(), arg: bad})


@pytest.mark.parametrize(("fn", "arg"), _cases(BOOL_ARGS))
def test_non_boolean_flag_in_a_batch_is_named(fn, arg):
    call, valid = FUNCTIONS[fn]
    with _raises_naming(arg) as info:
        call(**{**valid(), arg: np.array([0.0, 1.0, np.nan, 1.0])})
    assert "index (2,)" in str(info.value)


def _same(a, b) -> bool:
    """Equal results: plain values, tuples of them, or dataclasses (an ``EvasionPlan``) field by field."""
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(_same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    if isinstance(a, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, Params):
        return a == b
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


@pytest.mark.parametrize("fn", sorted(BOOL_ARGS))
@pytest.mark.parametrize("as_int", [0, 1])
def test_flags_accept_zero_and_one(fn, as_int):
    # 0 and 1 are read as False and True: the same result as the booleans, scalar and batched.
    call, valid = FUNCTIONS[fn]
    for batch in ((), (3,)):
        kw = {k: np.full(batch, v) if batch and k in NUMERIC_ARGS[fn] else v for k, v in valid().items()}
        ints = {**kw, **{arg: np.full(batch, as_int) if batch else as_int for arg in BOOL_ARGS[fn]}}
        bools = {**kw, **{arg: np.full(batch, bool(as_int)) if batch else bool(as_int) for arg in BOOL_ARGS[fn]}}
        assert _same(call(**ints), call(**bools))


@pytest.mark.parametrize("fn", sorted(NUMERIC_ARGS))
def test_non_broadcastable_shapes_are_named(fn):
    call, valid = FUNCTIONS[fn]
    first, last = NUMERIC_ARGS[fn][0], NUMERIC_ARGS[fn][-1]
    kw = valid()
    kw[first], kw[last] = np.full(3, kw[first]), np.full(4, kw[last])
    with pytest.raises(ValueError, match="do not broadcast") as info:
        call(**kw)
    assert f"{first}(3,)" in str(info.value) and f"{last}(4,)" in str(info.value)


def test_chain_unsafe_must_fit_the_batch():
    with _raises_naming("chain_unsafe"):
        plan_evasion(**_evasion_kwargs(), params=PARAMS, chain_unsafe=np.zeros(3, dtype=bool))


def test_plan_state_rejects_bad_times():
    plan = plan_evasion(**{**_evasion_kwargs(), "ego_px": np.zeros(4)}, params=PARAMS)
    for bad in (np.nan, np.inf, -1.0, "abc", None, np.array([0.0, -0.1, 0.0, 0.0])):
        with _raises_naming("t"):
            plan.state(bad)
    with _raises_naming("t"):
        plan.state(np.zeros(3))  # batch is (4,)


# --- the leader chain ---------------------------------------------------------------------------------------------

CHAIN = dict(p=[0.0, 30.0, 60.0], v=[25.0, 25.0, 25.0], promise_decel=[2.0, 2.0])
CHAIN_FUNCTIONS = [leader_chain, worst_case_leader_decel]


def _chain_call(fn, **overrides):
    return fn(**{**CHAIN, **overrides}, params=PARAMS)


@pytest.mark.parametrize("fn", CHAIN_FUNCTIONS)
@pytest.mark.parametrize("arg", ["p", "v", "promise_decel"])
@pytest.mark.parametrize("bad", [*NON_FINITE, "abc"], ids=["nan", "inf", "-inf", "word"])
def test_chain_bad_values_are_named(fn, arg, bad):
    values = list(CHAIN[arg])
    values[1] = bad
    with _raises_naming(arg):
        _chain_call(fn, **{arg: values if bad != "abc" else bad})


@pytest.mark.parametrize("fn", CHAIN_FUNCTIONS)
@pytest.mark.parametrize(
    ("overrides", "name"),
    [
        (dict(v=[25.0, -1.0, 25.0]), "v"),
        (dict(promise_decel=[2.0, -0.1]), "promise_decel"),
        (dict(promise_decel=[2.0, PARAMS.a_x_d + 0.1]), "promise_decel"),
        (dict(promise_decel=[2.0]), "promise_decel"),  # N = 2 leaders need 2 promises
        (dict(promise_decel=[2.0, 2.0, 2.0]), "promise_decel"),
        (dict(v=[25.0, 25.0]), "v"),  # p and v must describe the same vehicles
        (dict(human_driven=[True]), "human_driven"),
        (dict(human_driven=[True, np.nan]), "human_driven"),
        (dict(human_driven=["yes", "no"]), "human_driven"),
        (dict(p=[], v=[], promise_decel=[]), "p"),  # not even L(N+1)
        (dict(p=3.0, v=25.0, promise_decel=[]), "p"),  # no vehicle axis
    ],
)
def test_chain_bad_input_is_named(fn, overrides, name):
    with _raises_naming(name):
        _chain_call(fn, **overrides)


@pytest.mark.parametrize("fn", CHAIN_FUNCTIONS)
def test_chain_batches_must_broadcast(fn):
    p = np.tile(CHAIN["p"], (3, 1))
    with pytest.raises(ValueError, match=r"promise_decel\(4, 2\)"):
        fn(p, p * 0.0 + 25.0, np.full((4, 2), 2.0), PARAMS)


# --- Params ---------------------------------------------------------------------------------------------------

PARAM_FIELDS = ["a_x_a", "a_x_d", "a_y_m", "lane_width", "vehicle_width", "vehicle_length", "p_m", "p_m_human", "dt"]


@pytest.mark.parametrize("field", PARAM_FIELDS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -1.0, 0.0, "abc"], ids=["nan", "inf", "negative", "zero", "word"])
def test_params_field_errors_are_named(field, bad):
    with _raises_naming(field):
        Params(**{field: bad})


@pytest.mark.parametrize(
    ("overrides", "names"),
    [
        (dict(a_y_m=0.0), ["a_y_m"]),
        (dict(vehicle_width=3.5), ["vehicle_width", "lane_width"]),
        (dict(vehicle_width=4.0), ["vehicle_width", "lane_width"]),
        (dict(p_m=4.0), ["p_m", "vehicle_length"]),
        (dict(p_m_human=6.0), ["p_m_human", "p_m"]),
    ],
)
def test_params_inconsistent_geometry(overrides, names):
    with pytest.raises(ValueError) as info:
        Params(**overrides)
    for name in names:
        assert re.search(rf"\b{name}\b", str(info.value)), (name, str(info.value))


def test_params_unknown_key_is_named():
    with _raises_naming("p_min"):
        Params(p_min=7.0)


def test_params_are_frozen():
    params = Params()
    with _raises_naming("a_x_d"):
        params.a_x_d = 6.0
    assert params.a_x_d == 8.0


@pytest.mark.parametrize(
    "call",
    [
        lambda prm: safety.worst_case_leader_decel([20.0, 40.0], [30.0, 30.0], [0.5], prm),
        lambda prm: safety.leader_position(0.0, 30.0, 2.0, 1.0, prm),
        lambda prm: safety.lateral_evasion_time(1.0, 0.2, prm),
        lambda prm: safety.longitudinal_evasion(0.0, 30.0, 20.0, 30.0, 2.0, 1.0, prm),
        lambda prm: safety.follower_position(-20.0, 30.0, True, 1.0, prm),
        lambda prm: safety.evasion_exists(0.0, 1.0, 30.0, 0.2, 20.0, 30.0, 2.0, -20.0, 30.0, True, prm),
        lambda prm: safety.plan_evasion(0.0, 1.0, 30.0, 0.2, 20.0, 30.0, 2.0, -20.0, 30.0, True, prm),
    ],
)
def test_params_must_be_params(call):
    with pytest.raises(ValueError, match=r"params must be a safelane\.Params"):
        call({"a_x_d": 8.0})
