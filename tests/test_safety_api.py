"""The public evasion API's contract beyond its values: keyword defaults, NumPy scalars for scalar inputs, large
batches (evaluated in chunks) equal to small ones, and no floating-point warnings reaching the caller."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import scenarios
from safelane import Params
from safelane.safety import evasion_exists, follower_position, plan_evasion
from safelane.safety.evasion import CHUNK

PRM = Params()


def _margin_matters() -> dict:
    """L1 8.5 m ahead and F 8.5 m behind, everyone at 25 m/s, nobody braking: enough for p_m = 7, not for the
    human-driven p_m_human = 10."""
    return {**scenarios.open_gap_collaborative_follower(), "l1_p": 8.5, "l1_decel": 0.0, "f_p": -8.5}


@pytest.mark.parametrize("flag", ["leader_human", "follower_human"])
def test_neighbours_are_automated_unless_said_otherwise(flag):
    s = _margin_matters()
    assert bool(evasion_exists(**s, params=PRM)) is True
    assert bool(evasion_exists(**s, params=PRM, **{flag: False})) is True
    assert bool(evasion_exists(**s, params=PRM, **{flag: True})) is False
    assert bool(plan_evasion(**s, params=PRM).feasible) is True
    assert bool(plan_evasion(**s, params=PRM, **{flag: True}).feasible) is False


def test_scalar_inputs_give_numpy_scalars():
    exists = evasion_exists(**scenarios.open_gap_collaborative_follower(), params=PRM)
    assert type(exists) is np.bool_
    for aggressive in (True, False):
        pos = follower_position(-20.0, 25.0, aggressive, 1.0, PRM)
        assert type(pos) is np.float64


def _random_states(shape, rng) -> dict:
    """Random states of batch ``shape`` (2-D), with arguments of several broadcastable shapes."""
    u = rng.uniform
    return dict(ego_px=u(-1, 1, (shape[0], 1)), ego_py=u(-0.2, 2.5, shape), ego_vx=u(0, 30, shape),
                ego_vy=u(-1, 1, shape), l1_p=u(5, 40, shape), l1_v=u(0, 30, shape[-1:]), l1_decel=u(0, 8, shape),
                f_p=u(-40, -5, shape), f_v=u(0, 30, shape),
                follower_aggressive=rng.uniform(0, 1, shape) < 0.5)  # fmt: skip


def test_a_batch_larger_than_a_chunk_equals_its_rows_evaluated_apart():
    shape = (3, CHUNK // 2 + 7)  # 3 rows of fewer than CHUNK scenarios, together more: the chunked path
    s = _random_states(shape, np.random.default_rng(0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        big = evasion_exists(**s, params=PRM)
    assert big.dtype == np.bool_ and big.shape == shape
    rows = [evasion_exists(**{k: np.broadcast_to(v, shape)[i] for k, v in s.items()}, params=PRM) for i in range(3)]
    assert np.array_equal(big, np.stack(rows))
    assert big.any() and not big.all()


def test_no_floating_point_warnings_at_the_edges():
    edges = dict(ego_px=0.0, ego_py=np.array([0.0, 0.85, 1.75, 3.5]), ego_vx=np.array([0.0, 0.0, 30.0, 0.0]),
                 ego_vy=np.array([0.0, 0.0, -2.0, 0.0]), l1_p=np.array([7.0, 7.0, 100.0, 7.0]), l1_v=0.0,
                 l1_decel=np.array([0.0, 8.0, 8.0, 0.0]), f_p=-7.0, f_v=0.0,
                 follower_aggressive=np.array([False, True, False, True]))  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        evasion_exists(**edges, params=PRM)
        plan_evasion(**edges, params=PRM)
        follower_position(np.zeros(3), np.array([0.0, 5.0, 30.0]), np.array([False, False, True]), 0.0, PRM)
        follower_position(0.0, np.array([0.0, 5.0, 30.0]), False, np.array([0.0, 1.0, 100.0]), PRM)


def test_a_chain_unsafe_flag_that_does_not_broadcast_is_named():
    batch = {**scenarios.open_gap_collaborative_follower(), "ego_px": np.zeros(4)}
    with pytest.raises(ValueError, match=r"\bchain_unsafe\b"):
        plan_evasion(**batch, params=PRM, chain_unsafe=np.zeros(3, dtype=bool))


def test_evasion_cores_tolerance_reaches_the_leader_check():
    # evasion_core's tol is the feasibility tolerance of both checks: a leader gap 5 mm inside p_m (L1 stopped, the
    # ego and F stopped) passes with tol = 1 cm and fails with the default 1 nm.
    from safelane.safety._backend import ARRAY
    from safelane.safety.evasion import evasion_core

    s = {**scenarios.open_gap_collaborative_follower(), "ego_vx": 0.0, "l1_v": 0.0, "l1_p": PRM.p_m - 0.005, "f_v": 0.0}
    args = [np.atleast_1d(np.asarray(s[k], dtype=float)) for k in
            ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "f_p", "f_v")]  # fmt: skip
    aggressive = np.atleast_1d(s["follower_aggressive"])
    loose, _ = evasion_core(ARRAY, *args, aggressive, PRM.p_m, PRM.p_m, PRM, tol=0.01)
    tight, _ = evasion_core(ARRAY, *args, aggressive, PRM.p_m, PRM.p_m, PRM)
    assert loose[0] and not tight[0]


def test_follower_check_spans_a_return_of_exactly_one_second():
    # Returning at 2 m/s from 1.25 m beyond y_s, braking the return at a_y_m: t_y_f = 1 s exactly. An aggressive F
    # 0.5 m outside p_m and 10 m/s faster is fine at t = 0 and too close within the second: no evasion.
    state = dict(ego_px=0.0, ego_py=2.1, ego_vx=20.0, ego_vy=-2.0, l1_p=100.0, l1_v=20.0, l1_decel=0.0,
                 f_p=-(PRM.p_m + 0.5), f_v=30.0, follower_aggressive=True)  # fmt: skip
    batch = {k: np.array([v]) for k, v in state.items()}
    plan = plan_evasion(**batch, params=PRM)
    assert plan.t_y_f[0] == 1.0 and not plan.feasible[0]
    assert not evasion_exists(**batch, params=PRM)[0]


def test_every_scenario_of_a_chunked_batch_is_evaluated():
    # Egos in the middle of their own lane have nothing to evade (an evasion exists); the first scenario of the
    # second batch is one without an evasion (an aggressive F 9 m behind, closing): both verdicts, first and last.
    n = 2 * CHUNK + 3
    inside = {k: np.full(n, v) for k, v in scenarios.open_gap_collaborative_follower().items()}
    inside["ego_py"][:], inside["ego_vy"][:] = 0.0, 0.0
    assert evasion_exists(**inside, params=PRM).all()
    for k, v in scenarios.tight_gap_aggressive_follower().items():
        inside[k][0] = v
    got = evasion_exists(**inside, params=PRM)
    assert not got[0] and got[1:].all()
