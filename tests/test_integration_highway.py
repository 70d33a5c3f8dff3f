"""The shield in highway-env (safelane.integrations.highway, issue 11): the wrapper's interface, the refusal of
other frequencies, the exact point-mass ego, and crashes by highway-env's own flag with and without the shield."""

from __future__ import annotations

import numpy as np
import pytest

REASON = "the highway-env integration needs the highway extra: pip install -e '.[highway]'"
pytest.importorskip("gymnasium", reason=REASON)
pytest.importorskip("highway_env", reason=REASON)

import gymnasium as gym  # noqa: E402

from safelane.integrations.highway import (  # noqa: E402
    HIGHWAY_CONFIG,
    NO_CUT_IN_CONFIG,
    SCENE_ENV_ID,
    NoCutInIDMVehicle,
    PointMassVehicle,
    PromiseIDMVehicle,
    SafeLaneShield,
    SuddenBrakeVehicle,
    highway_params,
    own_lane_leaders,
)

INFO_KEYS = {"shield", "intervened", "nominal_action", "executed_action", "reason", "cost", "crashed"}
FAST = {"observation": {"type": "LidarObservation"}}  # the default Kinematics observation is slow (pandas)


def reckless(env) -> np.ndarray:
    """Full authority: a_x_a and the lateral acceleration saturated toward the target-lane centre."""
    prm, ego = env.params, env.ego
    y, vy = (float(z) for z in env.frame.y(ego.position[1], ego.lateral_speed))
    return np.array([prm.a_x_a, np.clip(2.0 * (prm.lane_width - y) - 2.5 * vy, -prm.a_y_m, prm.a_y_m)])


def run(env, seed: int):
    env.reset(seed=seed)
    done, info = False, {}
    while not done:
        _, _, terminated, truncated, info = env.step(reckless(env))
        done = terminated or truncated
    return info


def scene(shield=True, duration=8, wrapper=None, **config):
    env = gym.make(SCENE_ENV_ID, config={**FAST, "duration": duration, **config})
    return SafeLaneShield(env, shield=shield, **(wrapper or {}))


def test_info_keys_and_spaces():
    env = scene()
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert info["target_lane"] == 0 and info["original_lane"] == 1
    prm = env.params
    assert np.allclose(env.action_space.low, [-prm.a_x_d, -prm.a_y_m])
    assert np.allclose(env.action_space.high, [prm.a_x_a, prm.a_y_m])
    _, _, _, _, info = env.step(np.array([0.0, 1.0]))
    assert INFO_KEYS <= set(info)
    assert info["shield"] in {"proceed", "hesitate", "abort", "completed"}
    assert isinstance(info["intervened"], bool) and isinstance(info["reason"], str)
    assert np.allclose(info["nominal_action"], [0.0, 1.0])
    assert info["executed_action"].shape == (2,) and info["cost"] in (0.0, 1.0)
    off = scene(shield=False)
    off.reset(seed=0)
    info = off.step(np.array([0.5, 1.0]))[4]
    assert info["shield"] == "off" and not info["intervened"]
    assert np.allclose(info["executed_action"], [0.5, 1.0])  # exact: Δv/dt is the command


def test_refuses_other_frequencies():
    with pytest.raises(ValueError, match=r"simulation_frequency.*policy_frequency"):
        SafeLaneShield(gym.make("highway-v0"))  # highway-env's defaults: 15 Hz simulation, 1 Hz policy
    with pytest.raises(ValueError, match="policy_frequency"):
        SafeLaneShield(gym.make("highway-v0", config={"simulation_frequency": 10, "policy_frequency": 5}))
    SafeLaneShield(gym.make("highway-v0", config={**HIGHWAY_CONFIG, **FAST}))  # 10 Hz / 10 Hz is accepted


def test_point_mass_ego_is_exact():
    """Braking at 8 m/s² from 25 m/s: the ego stops exactly at v²/(2a) and never reverses (highway-env's own
    Vehicle overshoots by 1.2 m and goes negative); the lateral motion is the exact parabola."""
    env = scene(shield=False)
    env.reset(seed=1)
    ego = env.ego
    assert isinstance(ego, PointMassVehicle) and env.unwrapped.vehicle is ego
    x0, y0, v0 = float(ego.position[0]), float(ego.position[1]), float(ego.speed)
    dt, a_y = env.params.dt, 0.7
    for k in range(1, 41):
        ego.command = ("accel", -8.0, -a_y)  # set directly: the host steps it exactly as given
        ego.step(dt)
        t = k * dt
        ts = min(t, v0 / 8.0)
        assert ego.speed == pytest.approx(max(v0 - 8.0 * t, 0.0), abs=1e-9)
        assert ego.position[0] == pytest.approx(x0 + v0 * ts - 4.0 * ts * ts, abs=1e-9)
        assert ego.position[1] == pytest.approx(y0 - 0.5 * a_y * t * t, abs=1e-9)
    assert ego.speed == 0.0
    # highway-env's own integration (old speed for the position) for comparison: the unsafe side
    from highway_env.vehicle.kinematics import Vehicle

    host = Vehicle(env.unwrapped.road, [x0, y0], 0.0, 25.0)
    host.action = {"steering": 0.0, "acceleration": -8.0}
    for _ in range(30):
        host.step(dt)
    assert host.position[0] - x0 > 25.0**2 / 16.0 + 1.0  # 3 s of braking: 1.1 m further than the exact stop
    for _ in range(2):
        host.step(dt)
    assert host.speed < 0.0


def test_wrapper_moves_the_ego_exactly_toward_the_target_lane():
    env = scene(shield=False, own_leader=None)
    env.reset(seed=2)
    ego, prm = env.ego, env.params
    x0, y0, v0 = float(ego.position[0]), float(ego.position[1]), float(ego.speed)
    for _ in range(5):
        env.step(np.array([1.0, 1.0]))
    t = 5 * prm.dt
    assert ego.position[0] == pytest.approx(x0 + v0 * t + 0.5 * t * t, abs=1e-9)
    assert ego.position[1] == pytest.approx(y0 - 0.5 * t * t, abs=1e-9)  # the target lane 0 lies at smaller y


def test_own_lane_leaders_fill():
    env = scene(own_leader="cruise")
    env.reset(seed=3)
    x, _, found = own_lane_leaders(env.unwrapped.road, env.ego, env.original_lane, 2)
    assert len(found) == 1 and np.isfinite(x[0]) and x[0] > env.ego.position[0] and np.isinf(x[1])
    env_empty = scene()
    env_empty.reset(seed=3)
    x, _, found = own_lane_leaders(env_empty.unwrapped.road, env_empty.ego, env_empty.original_lane, 1)
    assert found == [] and np.isinf(x[0])


def test_highway_params_match_the_host():
    prm = highway_params()
    assert (prm.lane_width, prm.vehicle_width, prm.vehicle_length) == (4.0, 2.0, 5.0)
    assert prm.dt == pytest.approx(0.1)


@pytest.mark.parametrize("decel", [4.0, 6.0, 8.0])
def test_shielded_reckless_policy_never_crashes_unshielded_does(decel):
    """8 episodes per deceleration (24 in all) with the shield: 0 crashes by highway-env's flag; the same policy
    unshielded crashes (so this test can fail)."""
    shielded = scene(decel=[decel])
    crashes = [run(shielded, seed)["crashed"] for seed in range(8)]
    assert sum(crashes) == 0
    unshielded = scene(shield=False, decel=[decel])
    infos = [run(unshielded, seed) for seed in range(4)]
    assert sum(i["crashed"] for i in infos) > 0
    assert all("crash" in i and i["crash"]["partner"] != "none" for i in infos if i["crashed"])


def highway(shield=True, **config):
    base = {**HIGHWAY_CONFIG, **FAST, "vehicles_count": 20, "duration": 10}
    return SafeLaneShield(gym.make("highway-v0", config={**base, **config}), shield=shield)


def test_two_lane_highway_v0_without_cut_ins_shielded_never_crashes():
    """Random highway-v0 traffic inside the shield's assumptions — two lanes, and during the manoeuvre no MOBIL lane
    change into the ego's lanes beside it or between it and its nearest leader there: 6 shielded episodes, 0 crashes
    by highway-env's flag; unshielded, the same traffic crashes (so this test can fail). The campaign runs 200."""
    shielded = highway(lanes_count=2, **NO_CUT_IN_CONFIG)
    infos = [run(shielded, seed) for seed in range(6)]
    assert all(isinstance(v, NoCutInIDMVehicle) for v in shielded.unwrapped.road.vehicles if v is not shielded.ego)
    assert [i["crashed"] for i in infos] == [False] * 6
    assert not any(i["cut_in"] for i in infos)
    unshielded = highway(shield=False, lanes_count=2, **NO_CUT_IN_CONFIG)
    assert sum(run(unshielded, seed)["crashed"] for seed in range(3)) > 0


def test_cut_in_is_reported_and_blocked():
    """highway-v0 seed 88 (four lanes, MOBIL): a vehicle moves into the target lane ahead of the straddling ego from
    the lane beyond it — ``info["cut_in"]``; with NoCutInIDMVehicle traffic the same seed has none."""
    info = run(highway(), 88)
    assert info["cut_in"]
    assert not run(highway(**NO_CUT_IN_CONFIG), 88)["cut_in"]


def test_import_hint_names_the_extra():
    from safelane.integrations import highway

    assert "safelane[highway]" in highway.INSTALL_HINT


def test_actuation_delay_and_sensing_bounds():
    """Issue 17 in highway-env: the wrapper's actuator executes each command 0.2 s late (the shield's config says
    so) and the shield takes the worst case over SensingBounds: 0 crashes by highway-env's flag on the scene with
    hard braking; the shield that does not know of the delay, on the same delayed actuator, crashes."""
    from safelane.shield import SensingBounds, ShieldConfig

    def delayed(config, **kw):
        env = gym.make(SCENE_ENV_ID, config={**FAST, "duration": 8, "decel": [8.0]})
        wrapper = SafeLaneShield(env, config=config, **kw)
        wrapper.delay_periods = 2  # the host's actuator delays by 0.2 s whatever the shield assumes
        return wrapper

    aware = delayed(ShieldConfig(actuation_delay_s=0.2), sensing=SensingBounds())
    assert sum(run(aware, seed)["crashed"] for seed in range(6)) == 0
    unaware = delayed(ShieldConfig(own_lane=False, sensing=False))
    assert sum(run(unaware, seed)["crashed"] for seed in range(6)) > 0


def connected_scene(promise=0.5, loss=0.0, **config):
    """The scene with F and L1..LN connected (L(N+1) not), the leaders held to ``promise``; the shield reads them
    through emulated V2X messages (``CV_all``)."""
    return scene(connected=True, promise=promise, wrapper={"connected": True, "promise": promise, "v2x_loss": loss,
                                                            "v2x_seed": 0}, **config)  # fmt: skip


def test_connected_scene_marks_the_platoon_and_the_chain_comes_from_v2x():
    env = connected_scene(promise=0.7, n_leaders=[3], decel=[8.0])
    assert env.variant == "CV_all"
    env.reset(seed=0)
    s = env.situation()
    assert int(s.n_connected[0]) == 3 and np.allclose(s.chain_promise[0, :3], 0.7)
    assert bool(s.f_connected[0]) and not bool(s.f_collaborative[0])  # F declares no intent: still aggressive
    chain = env.chain_v2x  # safelane.v2x.leader_arrays over the messages
    assert chain.n_connected == 3 and "not connected" in chain.reason and not chain.stale_ids
    by_role = {env.roles[id(v)]: v for v in env.unwrapped.road.vehicles if id(v) in env.roles}
    for name in ("L1", "L2", "L3"):
        vehicle = by_role[name]
        assert isinstance(vehicle, PromiseIDMVehicle) and vehicle.safelane_connected and vehicle.safelane_promise == 0.7
    assert isinstance(by_role["L4"], SuddenBrakeVehicle) and not getattr(by_role["L4"], "safelane_connected", False)
    assert by_role["F"].safelane_connected
    plain = scene(n_leaders=[3], decel=[8.0])  # highway-env's traffic is not connected by default
    plain.reset(seed=0)
    assert int(plain.situation().n_connected[0]) == 0
    assert not any(getattr(v, "safelane_connected", False) for v in plain.unwrapped.road.vehicles)


def test_connected_leaders_are_held_to_their_chain_bound():
    """L(N+1) brakes at 8 m/s²: each connected leader brakes at no more than its chain bound (max(promise, needed),
    from the true states), so L1 never brakes harder than the bound the shield's chain analysis gave it (the
    monitor records no breach); some leader does brake beyond its promise (an expected violation), and exactly."""
    from safelane.safety import leader_chain

    env = connected_scene(n_leaders=[3], decel=[8.0])
    beyond_promise = 0.0
    for seed in range(2):
        env.reset(seed=seed)
        held = [v for v in env.unwrapped.road.vehicles if isinstance(v, PromiseIDMVehicle)]
        done = False
        while not done:
            s = env.situation()
            n = int(s.n_connected[0])
            l1 = next(v for v in held if env.roles.get(id(v)) == "L1") if n else None
            bound = leader_chain(s.chain_x[0, : n + 1], s.chain_v[0, : n + 1], s.chain_promise[0, :n], env.params)
            x0, v0 = (float(l1.position[0]), float(l1.speed)) if l1 is not None else (0.0, 0.0)
            _, _, terminated, truncated, info = env.step(reckless(env))
            done = terminated or truncated
            for v in held:
                assert v.action["acceleration"] >= -v.safelane_bound - 1e-9
                assert v.safelane_promise - 1e-12 <= v.safelane_bound <= env.params.a_x_d
                beyond_promise = max(beyond_promise, -v.action["acceleration"] - v.safelane_promise)
            if l1 is not None and not l1.crashed:
                a = l1.action["acceleration"]
                assert a >= -float(bound.decel[0]) - 1e-9
                t = min(env.params.dt, v0 / -a) if a < 0 else env.params.dt  # exact motion, stopping at 0
                assert l1.position[0] == pytest.approx(x0 + v0 * t + 0.5 * a * t * t, abs=1e-9)
        assert not info["crashed"] and not env.shield.state.breach.any[0]
        assert not any(v.crashed for v in env.unwrapped.road.vehicles)
    assert beyond_promise > 1.0


def test_connected_shield_never_crashes_and_succeeds_at_least_as_often():
    """6 episodes with L(N+1) braking at 8 m/s² (seeds 0–5, N ∈ {1, 3}), the reckless policy: 0 crashes by
    highway-env's flag with the connected shield (CV_all over emulated V2X) and with the non-connected one on the
    same scenes; the connected shield completes the lane change at least as often (measured: 5 of 6 against 1)."""
    connected, plain = connected_scene(decel=[8.0]), scene(decel=[8.0])
    with_v2x = [run(connected, seed) for seed in range(6)]
    without = [run(plain, seed) for seed in range(6)]
    assert sum(i["crashed"] for i in with_v2x) == 0 and sum(i["crashed"] for i in without) == 0
    success = [sum(i["completed"] and not i["crashed"] for i in infos) for infos in (with_v2x, without)]
    assert success[0] >= success[1] and success[0] > 0, success


def test_v2x_loss_falls_back_and_never_crashes():
    """30 % message loss (seeded): stale senders end the chain (L(N+1) at a_x_d) and the Situation says so; 0
    crashes in 3 episodes."""
    env = connected_scene(loss=0.3, decel=[8.0], n_leaders=[3])
    stale_seen = False
    for seed in range(3):
        env.reset(seed=seed)
        done = False
        while not done:
            stale_seen = stale_seen or bool(env.chain_v2x is not None and env.chain_v2x.stale_ids)
            _, _, terminated, truncated, info = env.step(reckless(env))
            done = terminated or truncated
        assert not info["crashed"]
    assert stale_seen
    with pytest.raises(ValueError, match="v2x_loss"):
        SafeLaneShield(gym.make(SCENE_ENV_ID, config=FAST), connected=True, v2x_loss=1.5)


def campaign_highway(seed: int, others: bool):
    """benchmarks/highway_campaign.py's "highway-v0" case (highway-env's 4 lanes and MOBIL traffic, 20 vehicles, 10 s)
    under the shield, the reckless policy."""
    env = gym.make("highway-v0", config={**HIGHWAY_CONFIG, **FAST, "vehicles_count": 20, "duration": 10})
    return run(SafeLaneShield(env, others=others), seed)


def test_the_situation_carries_every_other_vehicle_once_in_the_shields_frame():
    env = SafeLaneShield(gym.make("highway-v0", config={**HIGHWAY_CONFIG, **FAST}))
    env.reset(seed=3)
    for _ in range(5):
        env.step(reckless(env))
    s = env.situation()
    road, frame = env.unwrapped.road, env.frame
    named = [v for v in road.vehicles if id(v) in env.roles and v is not env.ego]
    present = np.isfinite(s.others.x[0])
    assert present.sum() + len(named) == len(road.vehicles) - 1  # each vehicle once: a role or an other
    rest = [v for v in road.vehicles if v is not env.ego and id(v) not in env.roles]
    assert np.allclose(s.others.x[0], [v.position[0] for v in rest])
    assert np.allclose(s.others.y[0], [float(frame.y(v.position[1], 0.0)[0]) for v in rest])  # lane i at i * w
    assert not s.others.connected.any()
    bare = SafeLaneShield(gym.make("highway-v0", config={**HIGHWAY_CONFIG, **FAST}), others=False)
    bare.reset(seed=3)
    assert bare.situation().others is None


@pytest.mark.parametrize("seed", [88, 180])
def test_far_lane_cut_in_of_stock_traffic_is_avoided_with_the_world_model(seed):
    """The two crashes of the campaign's highway-v0 case before the world model: MOBIL moved a vehicle from the lane
    beyond the target lane into it ahead of the straddling ego. Without ``others`` the side contact happens and the
    blame rule names both (each moved laterally toward the other); with them the shield counts the vehicle in the
    target lane from the moment its RSS lateral worst case reaches it, and no crash happens."""
    before = campaign_highway(seed, others=False)
    assert before["crashed"] and before["crash"]["partner"] == "L1" and before["crash"]["partner_changing_lanes"]
    assert before["crash_blame"] in ("ego", "other", "both")
    after = campaign_highway(seed, others=True)
    assert not after["crashed"] and after["crash_blame"] is None


def test_a_decision_rule_that_responds_without_a_held_plan_is_executed_as_accelerations():
    """The RSS baseline's rule (variant ``RSS_matched``) answers a dangerous situation with a proper response —
    braking — coded as an abort but with no held plan to follow (``Decision.abort_motion`` has no rows): the wrapper
    executes its accelerations. It indexed the missing plan's knots and failed, on stock ``highway-v0``, seed 0,
    at its 15th step."""
    env = SafeLaneShield(gym.make("highway-v0", config={**HIGHWAY_CONFIG, **FAST}), variant="RSS_matched")
    env.reset(seed=0)
    for _ in range(40):
        _, _, terminated, truncated, info = env.step(reckless(env))
        if info["shield"] == "abort" or terminated or truncated:
            break
    assert info["shield"] == "abort", "the RSS rule did not respond here: the test needs a step where it does"
    assert info["executed_action"][0] < 0.0  # the proper response brakes
