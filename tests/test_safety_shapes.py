"""Shapes, dtypes and scalar/batched parity of every public safety function.

Shape tests run at batch shapes ``()``, ``(4,)`` and ``(2, 3)`` (Waymax's ``batch_dims``); batch shape ``()``
means Python floats, which take the pure-Python ``SCALAR`` backend. The parity tests feed the same ~1000 random
states one at a time (``SCALAR``) and as one batch (NumPy ``ARRAY``) and require agreement to ``1e-12``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane import Params
from safelane.safety import (
    ChainResult,
    EvasionPlan,
    LongitudinalEvasion,
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
BATCH_DIMS = [(), (4,), (2, 3)]
PARITY_N = 1000
PARITY_TOL = dict(rtol=1e-12, atol=1e-12)
N_LINKS = 3


def _sample(rng: np.random.Generator, shape, lo: float, hi: float, edges=()):
    """Uniform in ``[lo, hi]`` with about 10% of entries set to each value in ``edges`` (exact boundary values
    such as zero speed or ``a_x_d``, where the closed forms switch case)."""
    x = rng.uniform(lo, hi, shape)
    for edge in edges:
        x = np.where(rng.random(shape) < 0.1, edge, x)
    return x


def evasion_inputs(rng: np.random.Generator, shape) -> dict:
    """Random ego/``L1``/follower states of ``shape``: realistic and edge values (stopped vehicles, ``L1`` at
    constant speed or braking at ``a_x_d``, the ego in either lane or on ``y_s``)."""
    a_x_d = PARAMS.a_x_d
    ego_vx = _sample(rng, shape, 0.0, 35.0, edges=(0.0,))
    state = dict(
        ego_px=_sample(rng, shape, -5.0, 5.0),
        ego_py=_sample(rng, shape, -1.0, 4.0, edges=(PARAMS.y_safe,)),
        ego_vy=_sample(rng, shape, -2.5, 2.5, edges=(0.0,)),
        ego_vx=ego_vx,
        l1_p=_sample(rng, shape, 0.0, 60.0),
        l1_v=_sample(rng, shape, 0.0, 35.0, edges=(0.0,)),
        l1_decel=_sample(rng, shape, 0.0, a_x_d, edges=(0.0, a_x_d)),
        f_p=_sample(rng, shape, -60.0, -5.0),
        f_v=_sample(rng, shape, 0.0, 35.0, edges=(0.0,)),
        follower_aggressive=rng.random(shape) < 0.5,
    )
    state["l1_p"] = state["l1_p"] + state["ego_px"]
    return state


def chain_inputs(rng: np.random.Generator, shape, n_links: int = N_LINKS) -> dict:
    """Random chains ``L1..L(N+1)`` (last axis) with gaps of 2–40 m, some inside ``p_m``."""
    return dict(
        p=np.cumsum(rng.uniform(2.0, 40.0, (*shape, n_links + 1)), axis=-1),
        v=_sample(rng, (*shape, n_links + 1), 0.0, 35.0, edges=(0.0,)),
        promise_decel=_sample(rng, (*shape, n_links), 0.0, PARAMS.a_x_d, edges=(0.0,)),
        human_driven=rng.random((*shape, n_links)) < 0.3,
    )


def _as_inputs(state: dict, shape) -> dict:
    """Python floats/bools for batch shape ``()`` (the scalar path), arrays otherwise."""
    return {k: v.item() for k, v in state.items()} if shape == () else state


def _check(value, shape, dtype):
    assert np.shape(value) == shape
    assert np.asarray(value).dtype == dtype


# --- shapes and dtypes ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", BATCH_DIMS)
def test_lateral_evasion_time_shapes(shape):
    s = _as_inputs(evasion_inputs(np.random.default_rng(1), shape), shape)
    t_y_f, t_switch = lateral_evasion_time(s["ego_py"], s["ego_vy"], PARAMS)
    _check(t_y_f, shape, np.float64)
    _check(t_switch, shape, np.float64)


@pytest.mark.parametrize("shape", BATCH_DIMS)
def test_longitudinal_evasion_shapes(shape):
    s = _as_inputs(evasion_inputs(np.random.default_rng(2), shape), shape)
    t_y_f = _as_inputs({"t": np.random.default_rng(3).uniform(0.0, 4.0, shape)}, shape)["t"]
    result = longitudinal_evasion(s["ego_px"], s["ego_vx"], s["l1_p"], s["l1_v"], s["l1_decel"], t_y_f, PARAMS)
    assert isinstance(result, LongitudinalEvasion)
    dtypes = dict(feasible=np.bool_, t_x1=np.float64, t_x2=np.float64, case=np.int8, min_gap=np.float64)
    for field, dtype in dtypes.items():
        _check(getattr(result, field), shape, dtype)


@pytest.mark.parametrize("shape", BATCH_DIMS)
def test_evasion_exists_shapes(shape):
    s = _as_inputs(evasion_inputs(np.random.default_rng(4), shape), shape)
    _check(evasion_exists(**s, params=PARAMS), shape, np.bool_)
    _check(evasion_exists(**s, params=PARAMS, leader_human=True, follower_human=True), shape, np.bool_)


@pytest.mark.parametrize("shape", BATCH_DIMS)
def test_plan_evasion_shapes(shape):
    s = _as_inputs(evasion_inputs(np.random.default_rng(5), shape), shape)
    plan = plan_evasion(**s, params=PARAMS, chain_unsafe=True)
    assert isinstance(plan, EvasionPlan)
    special = dict(
        feasible=np.bool_, follows_leader=np.bool_, reason=np.uint8, follows_own=np.bool_, continues=np.bool_
    )
    for field in dataclasses.fields(plan):
        if field.name != "params":
            _check(getattr(plan, field.name), shape, special.get(field.name, np.float64))
    for value in plan.state(1.0):
        _check(value, shape, np.float64)
    for value in (*plan.position(0.5), *plan.velocity(0.5)):
        _check(value, shape, np.float64)


@pytest.mark.parametrize("shape", BATCH_DIMS)
def test_plan_state_broadcasts_times_against_the_batch(shape):
    plan = plan_evasion(**_as_inputs(evasion_inputs(np.random.default_rng(6), shape), shape), params=PARAMS)
    times = np.linspace(0.0, 5.0, 7).reshape((7,) + (1,) * len(shape))
    for value in plan.state(times):
        _check(value, (7, *shape), np.float64)


@pytest.mark.parametrize("shape", BATCH_DIMS)
def test_follower_and_leader_position_shapes(shape):
    s = _as_inputs(evasion_inputs(np.random.default_rng(7), shape), shape)
    _check(follower_position(s["f_p"], s["f_v"], s["follower_aggressive"], 1.5, PARAMS), shape, np.float64)
    _check(leader_position(s["l1_p"], s["l1_v"], s["l1_decel"], 1.5, PARAMS), shape, np.float64)


@pytest.mark.parametrize("shape", BATCH_DIMS)
@pytest.mark.parametrize("n_links", [0, 1, N_LINKS])
def test_chain_shapes(shape, n_links):
    c = chain_inputs(np.random.default_rng(8), shape, n_links)
    _check(worst_case_leader_decel(**c, params=PARAMS), shape, np.float64)
    result = leader_chain(**c, params=PARAMS)
    assert isinstance(result, ChainResult)
    _check(result.decel, (*shape, n_links + 1), np.float64)
    _check(result.required, (*shape, n_links), np.float64)
    _check(result.unsafe, shape, np.bool_)
    _check(result.l1_decel, shape, np.float64)


def test_inputs_broadcast_to_one_batch_shape():
    # Per-scenario ego states (2, 1) against per-follower states (3,): a (2, 3) batch.
    s = evasion_inputs(np.random.default_rng(9), (2, 3))
    s["ego_px"], s["ego_vx"] = s["ego_px"][:, :1], s["ego_vx"][:, :1]
    s["f_p"], s["f_v"] = s["f_p"][0], s["f_v"][0]
    s["l1_decel"] = 8.0
    _check(evasion_exists(**s, params=PARAMS), (2, 3), np.bool_)
    _check(plan_evasion(**s, params=PARAMS).t_x1, (2, 3), np.float64)


def test_chain_batch_broadcasts_promises():
    c = chain_inputs(np.random.default_rng(10), (4,))
    c["promise_decel"] = c["promise_decel"][0]  # one promise vector for all four chains
    _check(worst_case_leader_decel(**c, params=PARAMS), (4,), np.float64)


# --- scalar (SCALAR backend) vs batched (ARRAY backend) parity --------------------------------------------------


@pytest.fixture(scope="module")
def states():
    return evasion_inputs(np.random.default_rng(2024), (PARITY_N,))


def _one(state: dict, i: int) -> dict:
    return {k: v[i].item() for k, v in state.items()}


def _assert_parity(scalars: list, batched, name: str):
    expected = np.asarray(batched)
    got = np.array(scalars, dtype=expected.dtype)
    if expected.dtype.kind == "f":
        np.testing.assert_allclose(got, expected, err_msg=name, **PARITY_TOL)
    else:
        np.testing.assert_array_equal(got, expected, err_msg=name)


def test_parity_lateral(states):
    batched = lateral_evasion_time(states["ego_py"], states["ego_vy"], PARAMS)
    scalar = [lateral_evasion_time(states["ego_py"][i].item(), states["ego_vy"][i].item(), PARAMS)
              for i in range(PARITY_N)]  # fmt: skip
    for k, name in enumerate(("t_y_f", "t_switch")):
        _assert_parity([s[k] for s in scalar], batched[k], name)


def test_parity_longitudinal(states):
    t_y_f = np.random.default_rng(11).uniform(0.0, 4.0, PARITY_N)
    keys = ("ego_px", "ego_vx", "l1_p", "l1_v", "l1_decel")
    batched = longitudinal_evasion(*(states[k] for k in keys), t_y_f, PARAMS)
    scalar = [longitudinal_evasion(*(states[k][i].item() for k in keys), t_y_f[i].item(), PARAMS)
              for i in range(PARITY_N)]  # fmt: skip
    for field in dataclasses.fields(LongitudinalEvasion):
        _assert_parity([getattr(s, field.name) for s in scalar], getattr(batched, field.name), field.name)


@pytest.mark.parametrize("humans", [(False, False), (True, True)])
def test_parity_evasion_exists(states, humans):
    leader_human, follower_human = humans
    kw = dict(params=PARAMS, leader_human=leader_human, follower_human=follower_human)
    batched = evasion_exists(**states, **kw)
    assert 0.05 < batched.mean() < 0.95  # both outcomes are exercised
    _assert_parity([evasion_exists(**_one(states, i), **kw) for i in range(PARITY_N)], batched, "exists")


def test_parity_evasion_exists_chunked(states, monkeypatch):
    # Batches above CHUNK elements go through the chunked loop; it must not change a single answer.
    import safelane.safety.evasion as evasion

    whole = evasion_exists(**states, params=PARAMS)
    monkeypatch.setattr(evasion, "CHUNK", 64)
    np.testing.assert_array_equal(evasion_exists(**states, params=PARAMS), whole)
    two_d = {k: v.reshape(40, 25) for k, v in states.items()}
    np.testing.assert_array_equal(evasion_exists(**two_d, params=PARAMS), whole.reshape(40, 25))


def test_parity_plan_evasion(states):
    batched = plan_evasion(**states, params=PARAMS)
    scalar = [plan_evasion(**_one(states, i), params=PARAMS) for i in range(PARITY_N)]
    for field in dataclasses.fields(EvasionPlan):
        if field.name != "params":
            _assert_parity([getattr(s, field.name) for s in scalar], getattr(batched, field.name), field.name)
    t = np.random.default_rng(12).uniform(0.0, 6.0, PARITY_N)
    batched_state = batched.state(t)
    scalar_state = [s.state(t[i]) for i, s in enumerate(scalar)]
    for k, name in enumerate(("p_x", "p_y", "v_x", "v_y")):
        _assert_parity([s[k] for s in scalar_state], batched_state[k], name)


def test_parity_positions(states):
    t = np.random.default_rng(13).uniform(0.0, 6.0, PARITY_N)
    follower = follower_position(states["f_p"], states["f_v"], states["follower_aggressive"], t, PARAMS)
    leader = leader_position(states["l1_p"], states["l1_v"], states["l1_decel"], t, PARAMS)
    scalar_f, scalar_l = [], []
    for i in range(PARITY_N):
        s = _one(states, i)
        scalar_f.append(follower_position(s["f_p"], s["f_v"], s["follower_aggressive"], t[i].item(), PARAMS))
        scalar_l.append(leader_position(s["l1_p"], s["l1_v"], s["l1_decel"], t[i].item(), PARAMS))
    _assert_parity(scalar_f, follower, "follower_position")
    _assert_parity(scalar_l, leader, "leader_position")


@pytest.mark.parametrize("n_links", [0, 1, N_LINKS])
def test_parity_chain(n_links):
    chains = chain_inputs(np.random.default_rng(14 + n_links), (PARITY_N,), n_links)
    batched = leader_chain(**chains, params=PARAMS)
    scalar = [leader_chain(**{k: v[i] for k, v in chains.items()}, params=PARAMS) for i in range(PARITY_N)]
    assert 0 < batched.unsafe.sum() < PARITY_N or n_links == 0
    for field in dataclasses.fields(ChainResult):
        expected = getattr(batched, field.name)
        got = np.stack([np.asarray(getattr(s, field.name)) for s in scalar])
        if expected.dtype.kind == "f":
            np.testing.assert_allclose(got, expected, err_msg=field.name, **PARITY_TOL)
        else:
            np.testing.assert_array_equal(got, expected, err_msg=field.name)


def test_min_follow_decel_numpy_path_equals_the_scalar_backend():
    """The NumPy fast path of ``min_follow_decel`` (raw divisions, masked) is the scalar formula, bit for bit,
    including zero slack, zero speeds and a leader that never brakes."""
    from safelane.safety._backend import ARRAY, SCALAR
    from safelane.safety.chain import min_follow_decel

    rng = np.random.default_rng(3)
    n = 5000
    slack, v_f, v_l, a_l = rng.uniform(-5, 40, n), rng.uniform(0, 35, n), rng.uniform(0, 35, n), rng.uniform(0, 8, n)
    slack[::9], v_f[::7], v_l[::5], a_l[::4] = 0.0, 0.0, 0.0, 0.0
    batched = min_follow_decel(ARRAY, slack, v_f, v_l, a_l)
    scalar = [min_follow_decel(SCALAR, *map(float, row)) for row in zip(slack, v_f, v_l, a_l, strict=True)]
    np.testing.assert_array_equal(batched, np.array(scalar))
    assert np.isinf(batched).any() and (batched == 0.0).any()
