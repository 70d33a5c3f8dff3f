"""The V2X staleness fallback at its boundaries, the documented output types, and the simulator's vectorized
fallback (:func:`safelane.v2x.received_chain`) against an independent per-row reference written here.

The reference (:func:`_reference_row`) reads the docstring of ``received_chain`` literally: walk the slots from
``L1``; a connected slot whose age is at most ``max_age_s`` (within ``1e-9`` s) extends the chain, except the
last slot; the first slot that does not is ``L(N+1)``. Each real vehicle is moved to ``now_s`` by the exact
constant-acceleration formula with stopping (fresh senders with their reported acceleration, everything else
braking at ``a_x_d``); every slot beyond ``L(N+1)`` is padding ``1e6`` m apart ahead of it at its speed.
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.v2x import (
    MAX_AGE_S,
    SensedVehicle,
    V2XMessage,
    chain_arrays,
    check_stream,
    extrapolate,
    follower_status,
    leader_arrays,
    received_chain,
)
from test_v2x import NOW
from test_v2x import message as v2x_message

PARAMS = Params()


def message(**overrides) -> V2XMessage:
    """``test_v2x``'s fresh cruising leader, without a planned-acceleration sequence."""
    return v2x_message(**{"planned_accel": (), **overrides})


def sensed(**overrides) -> SensedVehicle:
    fields = dict(vehicle_id="s", timestamp_s=NOW, position_m=200.0, speed_mps=20.0)
    return SensedVehicle(**{**fields, **overrides})


# --- ages and the staleness boundary ---------------------------------------------------------------------------


def test_message_age():
    msg = message(timestamp_s=0.75)
    assert msg.age_s(1.0) == 0.25
    assert msg.age_s(0.75) == 0.0
    assert message(timestamp_s=2.0).age_s(np.float64(2.5)) == 0.5
    with pytest.raises(ValueError, match="after now_s"):
        msg.age_s(0.5)
    with pytest.raises(ValueError, match="now_s must be finite"):
        msg.age_s(float("nan"))


def test_a_timestamp_exactly_the_clock_tolerance_ahead_is_accepted_as_age_zero():
    """Clocks on the dt grid disagree by rounding: a timestamp up to 1e-9 s after ``now_s`` is not an error.
    ``0.0 - 1e-9`` is exactly ``-1e-9`` in float64, the tolerance itself (inclusive)."""
    msg = message(timestamp_s=1e-9)
    assert msg.age_s(0.0) == 0.0
    chain = leader_arrays([msg, sensed(timestamp_s=0.0)], 0.0, PARAMS)
    assert chain.n_connected == 1
    assert chain.p[0] == msg.position_m  # age 0: not moved
    with pytest.raises(ValueError, match="after now_s"):
        message(timestamp_s=2e-9).age_s(0.0)


def test_max_age_zero_is_valid_and_an_age_of_exactly_the_tolerance_is_fresh():
    """``max_age_s = 0`` is allowed (finite, >= 0): only messages of age 0 count, within the 1e-9 s tolerance.
    ``1e-9 - 0.0 == 1e-9 == 0.0 + 1e-9``: the boundary itself, fresh; 2e-9 is stale."""
    fresh = [message(vehicle_id="a", timestamp_s=0.0), sensed(timestamp_s=0.0)]
    for now, n in ((0.0, 1), (1e-9, 1), (2e-9, 0)):
        chain = leader_arrays(fresh, now, PARAMS, max_age_s=0.0)
        assert chain.n_connected == n, now
        status = follower_status(message(vehicle_id="F", timestamp_s=0.0), now, PARAMS, max_age_s=0.0)
        assert status.connected == (n == 1) and status.stale == (n == 0)
        t = np.array([[0.0, now]])
        got_n, stale = received_chain(t, [[30.0, 200.0]], [[25.0, 20.0]], [[0.0, 0.0]], [[True, False]], now, PARAMS,
                                      max_age_s=0.0)[2:]  # fmt: skip
        assert got_n[0] == n and bool(stale[0, 0]) == (n == 0)


# --- reasons and statuses name the vehicle and its place -------------------------------------------------------


def test_reasons_name_the_place_of_l_n_plus_1():
    platoon = [message(vehicle_id="a"), message(vehicle_id="b", position_m=60.0), sensed(vehicle_id="truck")]
    assert leader_arrays(platoon, NOW, PARAMS).reason == "L3 'truck' is not connected"
    assert leader_arrays(platoon[:2], NOW, PARAMS).reason == "L2 'b' is the last known leader"
    assert leader_arrays(platoon[:1], NOW, PARAMS).reason == "L1 'a' is the last known leader"
    stale = [message(vehicle_id="a"), message(vehicle_id="b", position_m=60.0, timestamp_s=0.0)]
    reason = leader_arrays(stale, NOW, PARAMS).reason
    assert reason.startswith("L2 'b' stale: age 1 s > max_age_s 0.3 s")


def test_follower_status_reasons_and_intent():
    none = follower_status(None, NOW, PARAMS)
    assert none.reason == "no message: not connected" and none.intent is None
    stale = follower_status(message(vehicle_id="F", intent="collaborative", timestamp_s=0.0), NOW, PARAMS)
    assert (stale.connected, stale.stale, stale.collaborative) == (False, True, False)
    assert stale.intent == "collaborative"  # what it declared, though it does not count
    assert stale.reason.startswith("F 'F' stale")
    fresh = follower_status(message(vehicle_id="F", intent="aggressive"), NOW, PARAMS)
    assert fresh.intent == "aggressive" and fresh.reason == "fresh; intent 'aggressive'"


def test_stream_error_names_the_first_vehicle():
    with pytest.raises(ValueError, match="differs from 'L1'"):
        check_stream([message(timestamp_s=0.0), message(vehicle_id="other", timestamp_s=0.1)])


# --- documented output types -----------------------------------------------------------------------------------


def test_leader_chain_arrays_have_the_documented_dtypes_also_for_n_zero():
    for leaders in ([sensed()], [message(vehicle_id="a"), sensed()]):
        chain = leader_arrays(leaders, NOW, PARAMS)
        assert chain.human_driven.dtype == bool and chain.promise_decel.dtype == np.float64
        assert chain.p.dtype == chain.v.dtype == np.float64


def test_chain_arrays_of_an_empty_batch():
    """No scenario: ``B = 0`` at the smallest width ``K = 1`` (every chain has at least ``L(N+1)``)."""
    batch = chain_arrays([], NOW, PARAMS)
    assert batch.p.shape == batch.v.shape == batch.valid.shape == (0, 1)
    assert batch.promise_decel.shape == batch.human_driven.shape == (0, 0)
    assert batch.n_connected.shape == (0,) and batch.n_connected.dtype.kind == "i"


def test_chain_arrays_dtypes_and_human_mask():
    scenarios = [[message(vehicle_id="a", human_driven=True), message(vehicle_id="b", position_m=60.0), sensed()]]
    batch = chain_arrays(scenarios, NOW, PARAMS)
    assert batch.human_driven.dtype == bool and batch.valid.dtype == bool
    assert batch.n_connected.dtype.kind == "i"
    np.testing.assert_array_equal(~batch.human_driven, [[False, True]])


def test_chain_arrays_pass_max_age_on():
    """A 0.5 s old leader is stale by default and fresh with ``max_age_s = 0.6``, in the batch as alone."""
    pair = [message(vehicle_id="a", timestamp_s=0.5), message(vehicle_id="b", timestamp_s=0.5, position_m=60.0)]
    for max_age in (MAX_AGE_S, 0.6):
        batch = chain_arrays([pair], NOW, PARAMS, max_age_s=max_age)
        alone = leader_arrays(pair, NOW, PARAMS, max_age_s=max_age)
        assert batch.n_connected[0] == alone.n_connected == (1 if max_age > 0.5 else 0)
        assert batch.stale_ids[0] == alone.stale_ids


def test_extrapolate_returns_float64_computed_in_float64():
    """Inputs of any dtype are computed in float64: float32 inputs give the float64 result of the same values."""
    p, v, a, dt = np.float32(100.1), np.float32(20.3), np.float32(-1.7), np.float32(0.3)
    got = extrapolate(p, v, a, dt)
    want = extrapolate(float(p), float(v), float(a), float(dt))
    assert got[0].dtype == got[1].dtype == np.float64
    assert got[0] == want[0] and got[1] == want[1]
    # Hand check of the float64 value: p + v t + a t²/2.
    assert want[0] == pytest.approx(float(p) + float(v) * float(dt) + 0.5 * float(a) * float(dt) ** 2, abs=1e-12)
    ints = extrapolate(0, 10, -2, 1)
    assert ints[0].dtype == np.float64 and float(ints[0]) == 9.0 and float(ints[1]) == 8.0


# --- received_chain against an independent per-row reference ---------------------------------------------------


def _reference_row(t, p, v, a, connected, now, max_age, a_x_d):
    """The docstring of received_chain, one row at a time, in plain Python (see the module docstring)."""
    k = len(p)
    ages = [max(now - ti, 0.0) for ti in t]
    stale = [bool(connected[j]) and ages[j] > max_age + 1e-9 for j in range(k)]
    n = 0
    while n < k - 1 and connected[n] and not stale[n]:
        n += 1
    out_p, out_v = [], []
    for j in range(n + 1):
        acc = a[j] if connected[j] and not stale[j] else -a_x_d
        tau = ages[j]
        if acc < 0.0 and v[j] + acc * tau < 0.0:  # stops inside: the braking distance
            out_p.append(p[j] + v[j] * v[j] / (-2.0 * acc))
            out_v.append(0.0)
        else:
            out_p.append(p[j] + v[j] * tau + 0.5 * acc * tau * tau)
            out_v.append(v[j] + acc * tau)
    for j in range(n + 1, k):
        out_p.append(out_p[n] + 1e6 * (j - n))
        out_v.append(out_v[n])
    return np.array(out_p), np.array(out_v), n, np.array(stale)


def _random_messages(rng, n, k, now):
    t = now - rng.choice([0.0, 0.1, 0.2, 0.3, 0.3 + 1e-6, 0.5, 1.0, 3.0], size=(n, k))
    p = np.cumsum(rng.uniform(8.0, 25.0, size=(n, k)), 1)
    v = rng.uniform(0.0, 30.0, size=(n, k))
    v[rng.uniform(size=(n, k)) < 0.1] = 0.0
    a = rng.uniform(-6.0, 1.5, size=(n, k))
    connected = rng.uniform(size=(n, k)) < 0.85
    return t, p, v, a, connected


@pytest.mark.parametrize(("k", "max_age"), [(1, MAX_AGE_S), (2, MAX_AGE_S), (5, MAX_AGE_S), (5, 0.45), (4, 0.0)])
def test_received_chain_matches_the_reference_including_the_padding(k, max_age):
    rng = np.random.default_rng(100 + k)
    n_rows, now = 300, 10.0
    t, p, v, a, connected = _random_messages(rng, n_rows, k, now)
    connected[:5] = True  # whole rows fresh and connected: the last slot is L(N+1)
    t[:5] = now
    got_p, got_v, got_n, got_stale = received_chain(t, p, v, a, connected, now, PARAMS, max_age_s=max_age)
    assert got_p.dtype == got_v.dtype == np.float64 and got_n.shape == (n_rows,)
    padded = 0
    for i in range(n_rows):
        ref_p, ref_v, ref_n, ref_stale = _reference_row(t[i], p[i], v[i], a[i], connected[i], now, max_age,
                                                        PARAMS.a_x_d)  # fmt: skip
        assert got_n[i] == ref_n
        np.testing.assert_allclose(got_p[i], ref_p, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(got_v[i, ref_n + 1 :], got_v[i, ref_n])  # padding at L(N+1)'s speed
        np.testing.assert_allclose(got_v[i], ref_v, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(got_stale[i], ref_stale)
        padded += k - 1 - ref_n
    assert k == 1 or padded > n_rows // 2
    assert k == 1 or (got_n == k - 1).sum() >= 5


def test_received_chain_accepts_any_numeric_dtype_and_integer_masks():
    """The result depends on the values only: float32 inputs and a 0/1 ``connected`` give what the same values as
    float64 and bool give. (Timestamps spread over ``[0, now]``: ``now - t`` is then inexact in float32 where
    ``t < now / 2``, so an age computed in float32 would differ.)"""
    rng = np.random.default_rng(7)
    now = 1.0
    t, p, v, a, connected = _random_messages(rng, 200, 4, now)
    t = rng.uniform(0.0, now, t.shape)
    t32, p32, v32, a32 = (x.astype(np.float32) for x in (t, p, v, a))
    want = received_chain(*(x.astype(np.float64) for x in (t32, p32, v32, a32)), connected, now, PARAMS)
    got = received_chain(t32, p32, v32, a32, connected.astype(np.int64), now, PARAMS)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)
    assert got[0].dtype == np.float64 and got[3].dtype == bool
