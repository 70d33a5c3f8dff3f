"""V2X messages: validation, staleness fallback, conversion into the leader-chain arrays."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import safelane
from safelane import Params
from safelane.safety import leader_chain, worst_case_leader_decel
from safelane.v2x import (
    MAX_AGE_S,
    ChainBatch,
    SensedVehicle,
    V2XMessage,
    chain_arrays,
    check_batch,
    check_stream,
    extrapolate,
    follower_status,
    leader_arrays,
)

PARAMS = Params()
NOW = 1.0


def message(**overrides) -> V2XMessage:
    """A fresh autonomous leader cruising at 25 m/s, sent at ``NOW``."""
    fields = dict(
        vehicle_id="L1",
        timestamp_s=NOW,
        position_m=30.0,
        speed_mps=25.0,
        accel_mps2=0.0,
        promise_decel=2.0,
        promise_accel=1.0,
        planned_accel=(0.5, 0.0, -1.0),
        human_driven=False,
    )
    return V2XMessage(**{**fields, **overrides})


def connected_platoon(now: float = NOW) -> list[V2XMessage | SensedVehicle]:
    """Three fresh connected leaders (L2 human-driven) followed by a non-connected truck."""
    return [
        message(vehicle_id="a", timestamp_s=now, position_m=30.0),
        message(vehicle_id="b", timestamp_s=now, position_m=60.0, human_driven=True, promise_decel=4.0),
        message(vehicle_id="c", timestamp_s=now, position_m=95.0, speed_mps=24.0),
        SensedVehicle(vehicle_id="truck", timestamp_s=now, position_m=130.0, speed_mps=22.0),
    ]


def stale_second_leader() -> list[V2XMessage | SensedVehicle]:
    """L2's last message is 0.5 s old: the chain must stop there, dropping L3 and the truck."""
    platoon = connected_platoon()
    platoon[1] = message(vehicle_id="b", timestamp_s=NOW - 0.5, position_m=50.0, speed_mps=20.0, accel_mps2=1.0)
    return platoon


# --- validation: one case per rule per field -------------------------------------------------------------------

BAD_FIELDS = [
    ("vehicle_id", "", "''"),
    ("timestamp_s", math.nan, "nan"),
    ("timestamp_s", math.inf, "inf"),
    ("position_m", math.nan, "nan"),
    ("position_m", -math.inf, "-inf"),
    ("speed_mps", math.inf, "inf"),
    ("speed_mps", -0.1, "-0.1"),
    ("accel_mps2", math.nan, "nan"),
    ("promise_decel", math.inf, "inf"),
    ("promise_decel", -1.0, "-1.0"),
    ("promise_accel", math.nan, "nan"),
    ("promise_accel", -0.5, "-0.5"),
    ("planned_accel", (0.0, math.nan), "nan"),
    ("planned_accel", (0.0, -2.5), "-2.5"),  # below -promise_decel = -2
    ("planned_accel", (1.5,), "1.5"),  # above promise_accel = 1
    ("human_driven", "maybe", "maybe"),
    ("intent", "friendly", "friendly"),
    ("unknown_field", 1.0, "1.0"),
]


@pytest.mark.parametrize(("field", "value", "shown"), BAD_FIELDS)
def test_invalid_field_names_field_and_value(field, value, shown):
    with pytest.raises(ValueError) as info:
        message(**{field: value})
    assert field in str(info.value)
    assert shown in str(info.value)


@pytest.mark.parametrize(("field", "value", "shown"), [("speed_mps", -1.0, "-1.0"), ("position_m", math.nan, "nan")])
def test_invalid_sensed_vehicle(field, value, shown):
    fields = dict(vehicle_id="x", timestamp_s=0.0, position_m=0.0, speed_mps=1.0)
    with pytest.raises(ValueError, match=field) as info:
        SensedVehicle(**{**fields, field: value})
    assert shown in str(info.value)


@pytest.mark.parametrize(("field", "limit"), [("promise_decel", "a_x_d"), ("promise_accel", "a_x_a")])
def test_promise_wider_than_mechanical_limit(field, limit):
    too_wide = getattr(PARAMS, limit) + 0.5
    msg = message(**{field: too_wide})  # the bare message does not know the params
    pattern = f"{field}={too_wide!r}.*{limit}"
    with pytest.raises(ValueError, match=pattern):
        msg.check_limits(PARAMS)
    with pytest.raises(ValueError, match=pattern):
        V2XMessage.model_validate(msg.model_dump(), context={"params": PARAMS})
    with pytest.raises(ValueError, match=pattern):
        leader_arrays([msg, message(vehicle_id="L2", position_m=60.0)], NOW, PARAMS)
    with pytest.raises(ValueError, match=pattern):
        follower_status(msg, NOW, PARAMS)


def test_promise_at_the_mechanical_limits_is_valid():
    msg = message(promise_decel=PARAMS.a_x_d, promise_accel=PARAMS.a_x_a, planned_accel=(-PARAMS.a_x_d, PARAMS.a_x_a))
    assert msg.check_limits(PARAMS) is msg


def test_reported_accel_may_exceed_the_promise():
    # An expected violation (braking harder for its own safety) is reported, not rejected.
    assert message(accel_mps2=-6.0).accel_mps2 == -6.0


def test_planned_accel_accepts_an_array():
    assert message(planned_accel=np.array([0.5, -1.0])).planned_accel == (0.5, -1.0)


def test_message_is_frozen():
    with pytest.raises(ValueError, match="frozen"):
        message().speed_mps = 3.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("timestamps", "pattern"),
    [((0.0, 0.2, 0.1), r"timestamp_s=0\.1 at message 2.*out of order"), ((0.0, 0.1, 0.1), r"timestamp_s=0\.1")],
)
def test_stream_out_of_order_timestamps(timestamps, pattern):
    with pytest.raises(ValueError, match=pattern):
        check_stream([message(timestamp_s=t) for t in timestamps])


def test_stream_of_two_vehicles_is_rejected():
    with pytest.raises(ValueError, match="vehicle_id='other'"):
        check_stream([message(timestamp_s=0.0), message(vehicle_id="other", timestamp_s=0.1)])


def test_stream_in_order_passes():
    msgs = [message(timestamp_s=t) for t in (0.0, 0.1, 0.2)]
    assert check_stream(msgs) == tuple(msgs)


def test_duplicated_ids_in_one_batch():
    batch = [message(vehicle_id="a"), SensedVehicle(vehicle_id="a", timestamp_s=NOW, position_m=80.0, speed_mps=20.0)]
    with pytest.raises(ValueError, match=r"vehicle_id='a' is duplicated.*entries 0 and 1"):
        check_batch(batch)
    with pytest.raises(ValueError, match="duplicated"):
        leader_arrays(batch, NOW, PARAMS)


def test_message_from_the_future_is_an_error():
    with pytest.raises(ValueError, match=r"timestamp_s=1\.5 .* after now_s=1\.0"):
        leader_arrays([message(timestamp_s=1.5)], NOW, PARAMS)


@pytest.mark.parametrize("bad", [-0.1, math.nan])
def test_bad_max_age(bad):
    with pytest.raises(ValueError, match="max_age_s"):
        leader_arrays(connected_platoon(), NOW, PARAMS, max_age_s=bad)


def test_empty_leader_list():
    with pytest.raises(ValueError, match="at least one vehicle"):
        leader_arrays([], NOW, PARAMS)


# --- staleness: the conservative fallback ----------------------------------------------------------------------


def test_default_max_age_is_three_control_periods():
    assert pytest.approx(3 * PARAMS.dt) == MAX_AGE_S


def test_age_of_exactly_max_age_on_the_dt_grid_is_fresh():
    # 1.0 − 0.7 = 0.30000000000000004 in float64; still three periods.
    chain = leader_arrays([message(vehicle_id="a", timestamp_s=0.7), message(vehicle_id="b")], 1.0, PARAMS)
    assert chain.n_connected == 1
    assert chain.stale_ids == ()


def test_stale_leader_counts_as_non_connected_and_says_so():
    chain = leader_arrays(stale_second_leader(), NOW, PARAMS)
    assert chain.n_connected == 1
    assert chain.ids == ("a", "b")
    assert chain.dropped_ids == ("c", "truck")
    assert chain.stale_ids == ("b",)
    assert "L2 'b'" in chain.reason and "stale" in chain.reason and "non-connected" in chain.reason


def test_larger_max_age_keeps_the_stale_leader():
    chain = leader_arrays(stale_second_leader(), NOW, PARAMS, max_age_s=0.6)
    assert chain.n_connected == 3
    assert chain.stale_ids == ()


def test_stale_l1_gives_n_zero_and_the_mechanical_worst_case():
    chain = leader_arrays([message(timestamp_s=0.0), message(vehicle_id="L2", position_m=60.0)], NOW, PARAMS)
    assert chain.n_connected == 0
    assert chain.promise_decel.shape == (0,)
    assert worst_case_leader_decel(chain.p, chain.v, chain.promise_decel, PARAMS) == PARAMS.a_x_d


# --- truncation ------------------------------------------------------------------------------------------------


def test_chain_stops_at_the_first_non_connected_vehicle():
    chain = leader_arrays(connected_platoon(), NOW, PARAMS)
    assert chain.n_connected == 3
    assert chain.ids == ("a", "b", "c", "truck")
    assert chain.dropped_ids == ()
    np.testing.assert_array_equal(chain.promise_decel, [2.0, 4.0, 2.0])
    np.testing.assert_array_equal(chain.human_driven, [False, True, False])
    assert "'truck' is not connected" in chain.reason


def test_vehicles_beyond_a_non_connected_leader_are_dropped():
    platoon = connected_platoon()
    platoon.insert(1, SensedVehicle(vehicle_id="van", timestamp_s=NOW, position_m=45.0, speed_mps=25.0))
    chain = leader_arrays(platoon, NOW, PARAMS)
    assert chain.n_connected == 1
    assert chain.ids == ("a", "van")
    assert chain.dropped_ids == ("b", "c", "truck")


def test_all_connected_makes_the_last_one_l_n_plus_1():
    chain = leader_arrays(connected_platoon()[:3], NOW, PARAMS)
    assert chain.n_connected == 2
    assert chain.ids == ("a", "b", "c")
    assert "last known leader" in chain.reason


# --- extrapolation: hand-computed golden cases -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("p", "v", "a", "age", "p_now", "v_now"),
    [
        (100.0, 20.0, -2.0, 0.2, 100.0 + 4.0 - 0.04, 19.6),  # braking, still moving
        (100.0, 1.0, -8.0, 0.3, 100.0 + 1.0 / 16.0, 0.0),  # stops after 0.125 s, then stays
        (100.0, 10.0, 2.0, 0.1, 100.0 + 1.0 + 0.01, 10.2),  # accelerating
        (100.0, 0.0, -3.0, 0.3, 100.0, 0.0),  # at rest, braking: no reversing
    ],
)
def test_fresh_message_extrapolated_with_reported_accel(p, v, a, age, p_now, v_now):
    msg = message(timestamp_s=NOW - age, position_m=p, speed_mps=v, accel_mps2=a)
    chain = leader_arrays(
        [msg, SensedVehicle(vehicle_id="far", timestamp_s=NOW, position_m=500.0, speed_mps=v)], NOW, PARAMS
    )
    assert chain.p[0] == pytest.approx(p_now, abs=1e-12)
    assert chain.v[0] == pytest.approx(v_now, abs=1e-12)


def test_stale_l_n_plus_1_extrapolated_as_braking_at_a_x_d():
    # b: 20 m/s at 50 m, 0.5 s ago, reporting +1 m/s²; worst case is braking at 8 m/s² since then.
    chain = leader_arrays(stale_second_leader(), NOW, PARAMS)
    assert chain.p[1] == pytest.approx(50.0 + 20.0 * 0.5 - 0.5 * 8.0 * 0.25)
    assert chain.v[1] == pytest.approx(16.0)


def test_sensed_l_n_plus_1_extrapolated_as_braking_at_a_x_d():
    truck = SensedVehicle(vehicle_id="truck", timestamp_s=NOW - 0.1, position_m=130.0, speed_mps=22.0)
    chain = leader_arrays([message(), truck], NOW, PARAMS)
    assert chain.p[1] == pytest.approx(130.0 + 2.2 - 0.04)
    assert chain.v[1] == pytest.approx(21.2)


@settings(max_examples=200, deadline=None)
@given(
    v=st.floats(0.0, 40.0),
    a=st.floats(-8.0, 3.0),
    age=st.floats(0.0, 1.0),
)
def test_extrapolate_matches_time_stepped_integration(v, a, age):
    n = 20_000
    h = age / n
    p_sim, v_sim = 0.0, v
    for _ in range(n):  # exact per step while moving; a step that would reverse stops at rest instead
        if a < 0.0 and v_sim + a * h < 0.0:
            p_sim += v_sim * v_sim / (-2.0 * a)
            v_sim = 0.0
            break
        p_sim += v_sim * h + 0.5 * a * h * h
        v_sim += a * h
    p_now, v_now = extrapolate(0.0, v, a, age)
    assert p_now == pytest.approx(p_sim, abs=1e-6)
    assert v_now == pytest.approx(v_sim, abs=1e-6)


def test_extrapolate_stops_exactly_at_rest():
    """Stopping inside the interval ends at speed exactly 0 and at the braking distance (no rounding residue)."""
    v, a = np.array([0.1095400068059238, 27.537869222837603]), np.array([-0.42831204867370987, -4.197615787694026])
    p_now, v_now = extrapolate(0.0, v, a, 20.0)  # v + a·(v/−a) rounds to 1e-17 and 4e-15 for these
    assert np.all(v_now == 0.0)
    np.testing.assert_allclose(p_now, v * v / (-2 * a), rtol=1e-14)


def test_extrapolate_broadcasts():
    p, v = extrapolate(np.zeros((2, 3)), 10.0, np.array([-1.0, 0.0, 1.0]), 0.1)
    assert p.shape == v.shape == (2, 3)


# --- feeding the safety engine ---------------------------------------------------------------------------------


def test_arrays_feed_worst_case_leader_decel():
    chain = leader_arrays(connected_platoon(), NOW, PARAMS)
    got = worst_case_leader_decel(chain.p, chain.v, chain.promise_decel, PARAMS, human_driven=chain.human_driven)
    want = worst_case_leader_decel(
        [30.0, 60.0, 95.0, 130.0], [25.0, 25.0, 24.0, 22.0], [2.0, 4.0, 2.0], PARAMS, human_driven=[0, 1, 0]
    )
    assert got == want
    assert 2.0 <= got <= PARAMS.a_x_d


def test_chain_arrays_shapes_mask_and_counts():
    scenarios = [connected_platoon(), stale_second_leader(), connected_platoon()[:1], connected_platoon()[:3]]
    batch = chain_arrays(scenarios, NOW, PARAMS)
    assert batch.p.shape == batch.v.shape == batch.valid.shape == (4, 4)
    assert batch.promise_decel.shape == batch.human_driven.shape == (4, 3)
    np.testing.assert_array_equal(batch.n_connected, [3, 1, 0, 2])
    np.testing.assert_array_equal(batch.valid.sum(axis=1), batch.n_connected + 1)
    assert batch.stale_ids == ((), ("b",), (), ())
    assert "stale" in batch.reasons[1]


def test_chain_arrays_per_scenario_now():
    pair = [message(vehicle_id="a", timestamp_s=0.5), message(vehicle_id="b", timestamp_s=0.5, position_m=60.0)]
    batch = chain_arrays([pair, pair], [1.0, 0.6], PARAMS)  # 0.5 s old (stale), then 0.1 s old (fresh)
    np.testing.assert_array_equal(batch.n_connected, [0, 1])
    assert batch.stale_ids == (("a", "b"), ())


def _each_row_alone_matches(batch: ChainBatch, scenarios) -> None:
    # Row by row (batch shape ()), so that the padding itself is what is tested.
    for b, scenario in enumerate(scenarios):
        c = leader_arrays(scenario, NOW, PARAMS)
        alone = leader_chain(c.p, c.v, c.promise_decel, PARAMS, human_driven=c.human_driven)
        padded = leader_chain(
            batch.p[b], batch.v[b], batch.promise_decel[b], PARAMS, human_driven=batch.human_driven[b]
        )
        assert padded.l1_decel == alone.l1_decel
        assert padded.unsafe == alone.unsafe
        np.testing.assert_array_equal(padded.decel[batch.valid[b]], alone.decel)


def test_chain_arrays_padding_is_neutral():
    scenarios = [connected_platoon(), stale_second_leader(), connected_platoon()[:1], connected_platoon()[:3]]
    _each_row_alone_matches(chain_arrays(scenarios, NOW, PARAMS), scenarios)


def test_chain_arrays_feed_the_batched_safety_engine():
    scenarios = [connected_platoon(), stale_second_leader(), connected_platoon()[:1], connected_platoon()[:3]]
    batch = chain_arrays(scenarios, NOW, PARAMS)
    got = worst_case_leader_decel(batch.p, batch.v, batch.promise_decel, PARAMS, human_driven=batch.human_driven)
    want = [
        worst_case_leader_decel(c.p, c.v, c.promise_decel, PARAMS, human_driven=c.human_driven)
        for c in (leader_arrays(s, NOW, PARAMS) for s in scenarios)
    ]
    np.testing.assert_array_equal(got, want)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.lists(st.tuples(st.floats(5.0, 40.0), st.floats(0.0, 35.0), st.integers(0, 3)), min_size=1, max_size=5),
        min_size=1,
        max_size=6,
    )
)
def test_chain_arrays_padding_is_neutral_on_random_chains(raw):
    """Random chains: gap, speed and kind (0 fresh AV, 1 fresh human, 2 stale, 3 sensed) of each leader."""
    scenarios = []
    for chain in raw:
        pos, vehicles = 0.0, []
        for k, (gap, speed, kind) in enumerate(chain):
            pos += gap
            if kind == 3:
                vehicles.append(SensedVehicle(vehicle_id=f"v{k}", timestamp_s=NOW, position_m=pos, speed_mps=speed))
                continue
            age = 1.0 if kind == 2 else 0.1
            vehicles.append(
                message(
                    vehicle_id=f"v{k}",
                    timestamp_s=NOW - age,
                    position_m=pos,
                    speed_mps=speed,
                    accel_mps2=-1.0,
                    human_driven=kind == 1,
                )
            )
        scenarios.append(vehicles)
    _each_row_alone_matches(chain_arrays(scenarios, NOW, PARAMS), scenarios)


# --- follower --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("follower", "connected", "stale", "collaborative"),
    [
        (None, False, False, False),
        (message(vehicle_id="F", intent="collaborative"), True, False, True),
        (message(vehicle_id="F", intent="aggressive"), True, False, False),
        (message(vehicle_id="F"), True, False, False),  # undeclared intent: not collaborative
        (message(vehicle_id="F", intent="collaborative", timestamp_s=NOW - 0.5), False, True, False),
    ],
)
def test_follower_status(follower, connected, stale, collaborative):
    status = follower_status(follower, NOW, PARAMS)
    assert (status.connected, status.stale, status.collaborative) == (connected, stale, collaborative)
    if stale:
        assert "stale" in status.reason


# --- determinism and exports -----------------------------------------------------------------------------------


def test_conversion_is_deterministic_and_does_not_touch_inputs():
    scenarios = [connected_platoon(), stale_second_leader()]
    before = [[v.model_dump() for v in s] for s in scenarios]
    first, second = chain_arrays(scenarios, NOW, PARAMS), chain_arrays(scenarios, NOW, PARAMS)
    for name in ("p", "v", "promise_decel", "human_driven", "valid", "n_connected"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    assert first.reasons == second.reasons
    assert [[v.model_dump() for v in s] for s in scenarios] == before


def test_json_round_trip():
    msg = message(intent="collaborative")
    assert V2XMessage.model_validate_json(msg.model_dump_json()) == msg


def test_exported_from_package():
    assert safelane.V2XMessage is V2XMessage
    assert safelane.leader_arrays is leader_arrays
    assert safelane.chain_arrays is chain_arrays
