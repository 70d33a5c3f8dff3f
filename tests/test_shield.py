"""safelane.shield as a standalone component (issue 10): driven from hand-written loops, not the simulator.

* On the simulator's own situations, a stateful ``Shield`` in a plain Python loop makes the simulator's decisions.
* A hand-written world (plain kinematics, a constant-speed leader, no safelane simulator) driven by the shield
  keeps its margins where the unshielded planner does not.
* Situations from V2X messages equal situations from arrays; bad situations are field-named errors.
* A custom traffic model runs through ``simulate``; explicit initial states through one constructor.
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params, V2XMessage
from safelane.planners.base import ExpertPlanner
from safelane.shield import ABORT, COMPLETED, HESITATE, PROCEED, LaneFrame, Shield, ShieldConfig, Situation
from safelane.sim import (
    SimConfig,
    TrafficHooks,
    explicit_scenarios,
    paper_scenarios,
    simulate,
    simulate_batch,
)
from safelane.sim.step import ClosedLoop
from safelane.v2x import SensedVehicle

PRM = Params()


class _Recording:
    """The expert planner, remembering every proposal it made."""

    def __init__(self):
        self.proposals = []

    def __call__(self, obs, prm):
        a = ExpertPlanner()(obs, prm)
        self.proposals.append(a)
        return a


@pytest.mark.parametrize("planner", ["CV_all", "CV_none"])
def test_shield_in_a_hand_written_loop_makes_the_simulators_decisions(planner):
    batch = paper_scenarios(planner, 3, 6.0, 200, np.random.default_rng(4))
    nominal = _Recording()
    cfg = SimConfig(assessment="observed")
    sim = ClosedLoop(batch, 0, PRM, cfg, nominal)
    s = sim.initial_state()
    situations, behaviours = [], []
    for _ in range(60):
        situations.append(sim.situation(s.t, s.ego, s.x, s.v, None, s.v[:, 0]))
        s, _, behaviour = sim.step(s)
        behaviours.append(behaviour)
    # The same situations and proposals through the public, stateful Shield — no simulator involved.
    shield = Shield(PRM, variant=planner, config=ShieldConfig(assessment="observed"))
    shield.reset(situations[0])
    for situation, proposal, expected in zip(situations, nominal.proposals, behaviours, strict=True):
        decision = shield.step(situation, proposal)
        np.testing.assert_array_equal(decision.behaviour, expected)
    assert {PROCEED, HESITATE, ABORT, COMPLETED} & set(np.concatenate(behaviours).tolist()) >= {PROCEED, ABORT}


def _world_step(x, v, a, dt):
    """Plain constant-acceleration kinematics with stopping (the hand-written world's integrator)."""
    t_stop = np.where(a < 0, np.minimum(v / np.where(a < 0, -a, 1.0), dt), dt)
    return x + v * t_stop + 0.5 * a * t_stop**2, np.where(t_stop < dt, 0.0, v + a * dt)


@pytest.mark.parametrize("shielded", [True, False])
def test_hand_written_world_with_the_shield_keeps_the_margin(shielded):
    """An aggressive merge behind a hard-braking, non-connected L1 in a world written here (no safelane simulator).
    With the shield, no gap to L1 goes below p_m while the ego is out of its lane; without it, some do."""
    rng = np.random.default_rng(0)
    b = 300
    ego = [np.zeros(b), np.zeros(b), np.full(b, 30.0), np.zeros(b)]
    l1 = [rng.uniform(12.0, 20.0, b), np.full(b, 30.0)]
    f = [rng.uniform(-25.0, -15.0, b), np.full(b, 30.0)]
    shield = Shield(PRM, variant="CV_none", config=ShieldConfig(assessment="truth", enabled=shielded))

    def situation(t):
        sit = Situation.from_arrays(t=t, ego=tuple(ego), follower=tuple(f), leaders=(l1[0][:, None], l1[1][:, None]),
                                    n_connected=0, params=PRM)  # fmt: skip
        return Situation(**{**sit.__dict__, "f_aggressive_truth": np.zeros(b, bool)})

    shield.reset(situation(0.0))
    worst = np.inf
    for k in range(80):
        sit = situation(k * PRM.dt)
        # Reckless: full speed ahead and full lateral authority toward the target lane.
        d = shield.step(sit, (np.full(b, PRM.a_x_a), np.full(b, PRM.a_y_m)))
        a_l1 = np.full(b, -PRM.a_x_d if k >= 5 else 0.0)  # L1 brakes as hard as it can from t = 0.5 s
        rows, _knots, px, vx, py, vy = d.abort_motion()
        ego_x0, ego_y0 = ego[0].copy(), ego[1].copy()
        ego[0], ego[2] = _world_step(ego[0], ego[2], d.a_x, PRM.dt)
        ego[1], ego[3] = ego[1] + ego[3] * PRM.dt + 0.5 * d.a_y * PRM.dt**2, ego[3] + d.a_y * PRM.dt
        if rows.size:  # an abort follows the held plan exactly
            ego[0][rows], ego[2][rows], ego[1][rows], ego[3][rows] = px[:, -1], vx[:, -1], py[:, -1], vy[:, -1]
        l1_x0 = l1[0].copy()
        l1[0], l1[1] = _world_step(l1[0], l1[1], a_l1, PRM.dt)
        f[0], f[1] = _world_step(f[0], f[1], np.minimum(0.0, -PRM.a_x_d * (ego[0] - f[0] < 15.0)), PRM.dt)
        # Sampled at the period's ends, each counted while the ego is out of its lane then.
        gap_start = np.where(ego_y0 > PRM.y_safe + 1e-9, l1_x0 - ego_x0, np.inf)
        gap_end = np.where(ego[1] > PRM.y_safe + 1e-9, l1[0] - ego[0], np.inf)
        worst = min(worst, float(np.minimum(gap_start, gap_end).min()))
    if shielded:
        assert worst >= PRM.p_m - 1e-6
    else:
        assert worst < PRM.p_m - 0.5


def test_situation_from_v2x_messages_equals_the_arrays():
    t = 5.0

    def msg(i, p, v, a=0.0, stamp=t):
        return V2XMessage(vehicle_id=f"L{i}", timestamp_s=stamp, position_m=p, speed_mps=v, accel_mps2=a,
                          promise_decel=0.5, promise_accel=0.5, human_driven=False)  # fmt: skip

    leaders = [msg(1, 20.0, 28.0), msg(2, 40.0, 29.0, -1.0, t - 0.1), SensedVehicle(vehicle_id="L3", timestamp_s=t,
               position_m=65.0, speed_mps=27.0)]  # fmt: skip
    follower = V2XMessage(vehicle_id="F", timestamp_s=t, position_m=-18.0, speed_mps=30.0, accel_mps2=0.0,
                          promise_decel=0.5, promise_accel=0.5, human_driven=False, intent="collaborative")
    from_msgs = Situation.from_v2x(t=t, ego=(0.0, 1.0, 30.0, 0.4), follower=follower, leaders=leaders, params=PRM)
    p2, v2 = 40.0 + 29.0 * 0.1 - 0.5 * 0.01, 29.0 - 0.1  # L2 extrapolated with its reported -1 m/s² for 0.1 s
    from_arrays = Situation.from_arrays(
        t=t, ego=(0.0, 1.0, 30.0, 0.4), follower=(-18.0, 30.0), leaders=([20.0, p2, 65.0], [28.0, v2, 27.0]),
        n_connected=2, f_connected=True, f_collaborative=True, params=PRM,
    )  # fmt: skip
    for name in ("chain_x", "chain_v", "chain_promise", "n_connected", "f_connected", "f_collaborative", "f_x"):
        np.testing.assert_allclose(getattr(from_msgs, name), getattr(from_arrays, name), rtol=0, atol=1e-12)
    decisions = []
    for sit in (from_msgs, from_arrays):
        shield = Shield(PRM, variant="CV_all")
        shield.reset(sit)
        decisions.append(shield.step(sit, (np.array([0.5]), np.array([1.0]))))
    assert decisions[0].behaviour == decisions[1].behaviour
    assert decisions[0].l1_decel == pytest.approx(decisions[1].l1_decel[0], abs=1e-12)
    stale = Situation.from_v2x(t=t + 1.0, ego=(0.0, 1.0, 30.0, 0.4), follower=follower, leaders=leaders, params=PRM)
    assert stale.n_connected[0] == 0 and not stale.f_connected[0] and stale.v2x_stale[0]


def test_lane_frame_maps_a_mirrored_simulator():
    """highway-env style: y grows to the right, the target lane on the left (smaller y)."""
    frame = LaneFrame(origin_y=8.0, sign=-1.0)
    sit = Situation.from_arrays(t=0.0, ego=(0.0, 7.0, 30.0, -0.5), follower=(-20.0, 30.0), leaders=([20.0], [30.0]),
                                n_connected=0, frame=frame, params=PRM)  # fmt: skip
    assert sit.ego_y[0] == pytest.approx(1.0) and sit.ego_vy[0] == pytest.approx(0.5)
    assert frame.y_back(1.5) == pytest.approx(-1.5)
    with pytest.raises(ValueError, match="sign must be"):
        LaneFrame(sign=2.0)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"ego_vx": np.array([np.nan])}, "ego_vx must be finite"),
        ({"chain_v": np.array([[-1.0]])}, "chain_v must be >= 0"),
        ({"n_connected": np.array([3])}, "n_connected must lie in"),
        ({"f_x": np.zeros(2)}, r"f_x must have shape \(1,\)"),
    ],
)
def test_bad_situations_name_the_field(change, match):
    sit = Situation.from_arrays(t=0.0, ego=(0.0, 0.0, 30.0, 0.0), follower=(-20.0, 30.0), leaders=([20.0], [30.0]),
                                n_connected=0, params=PRM)  # fmt: skip
    bad = Situation(**{**sit.__dict__, **change})
    shield = Shield(PRM)
    with pytest.raises(ValueError, match=match):
        shield.reset(bad)


def test_shield_errors_are_clear():
    shield = Shield(PRM)
    sit = Situation.from_arrays(t=0.0, ego=(0.0, 0.0, 30.0, 0.0), follower=(-20.0, 30.0), leaders=([20.0], [30.0]),
                                n_connected=0, params=PRM)  # fmt: skip
    with pytest.raises(RuntimeError, match=r"before Shield\.reset"):
        shield.step(sit, (np.zeros(1), np.zeros(1)))
    with pytest.raises(ValueError, match="unknown planner variant"):
        Shield(PRM, variant="CV_some")
    with pytest.raises(ValueError, match="unknown assessment"):
        ShieldConfig(assessment="psychic")


class _Tailgater:
    """A custom traffic model (the documented example): every leader holds its speed; F closes on L1 at full
    acceleration until 10 m behind, then matches L1 — no responsible following at all (outside the assumptions)."""

    def bind(self, batch, seed, params, config):
        def step(view):
            acc = np.zeros_like(view.x)
            close = view.x[:, 1] - view.x[:, 0] > 10.0
            acc[:, 0] = np.where(close, params.a_x_a, 0.0)
            return acc, None

        return step


def test_a_custom_traffic_model_runs_through_simulate():
    res = simulate("CV_all", 2, 3.0, 50, 0, traffic=_Tailgater()).table
    default = simulate("CV_all", 2, 3.0, 50, 0).table
    assert not res["success"].equals(default["success"]) or not res["min_gap_follower_m"].equals(
        default["min_gap_follower_m"]
    )
    still = TrafficHooks(follower_wish=lambda view, prm: np.zeros(len(view.x)))  # F wants to hold its speed
    hooks = simulate("CV_all", 2, 3.0, 50, 0, traffic=still)
    assert hooks.table["collision"].sum() == 0
    with pytest.raises(ValueError, match="unknown traffic model"):
        simulate("CV_all", 2, 3.0, 5, 0, traffic="nope")
    by_name = simulate("CV_all", 2, 3.0, 50, 0, traffic="paper_reactive").table
    assert not by_name.equals(default)


def test_explicit_scenarios_build_a_batch_from_states():
    batch = explicit_scenarios(
        ego=(0.0, [0.0, 1.0], 30.0, [0.0, 0.5]), follower=(-20.0, 30.0), leaders=([20.0, 40.0, 60.0], [30.0] * 3),
        planner="CV_all", decel_last=6.0, follower_aggressive=[False, True],
    )  # fmt: skip
    assert len(batch) == 2 and batch.x.shape == (2, 4) and (batch.n_connected == 2).all()
    assert batch.connected[:, 1:3].all() and not batch.connected[:, 3].any()
    table = simulate_batch(batch, seed=0, config=SimConfig(assessment="truth")).table
    assert not table["collision"].any()
    with pytest.raises(ValueError, match="increase along the chain"):
        explicit_scenarios(ego=(0, 0, 30, 0), follower=(-20, 30), leaders=([40.0, 20.0], [30.0, 30.0]))
    with pytest.raises(ValueError, match="behind L1"):
        explicit_scenarios(ego=(0, 0, 30, 0), follower=(25, 30), leaders=([20.0], [30.0]))


def test_a_registered_assessment_plugs_in_by_name():
    """The assessment is a small protocol: registering one and naming it in ShieldConfig is all it takes."""
    from safelane.shield import policies

    class Pessimist(policies.ObservedAssessment):
        def aggressive(self, state, situation):
            return np.ones(len(situation), bool)

    policies.ASSESSMENTS["pessimist"] = Pessimist()
    try:
        sit = Situation.from_arrays(t=0.0, ego=(0.0, 0.0, 30.0, 0.0), follower=(-20.0, 30.0), leaders=([20.0], [30.0]),
                                    n_connected=0, params=PRM)  # fmt: skip
        shield = Shield(PRM, variant="CV_none", config=ShieldConfig(assessment="pessimist"))
        shield.reset(sit)
        assert shield.step(sit, (np.zeros(1), np.zeros(1))).f_aggressive.all()
        truth = Situation(**{**sit.__dict__, "f_aggressive_truth": np.zeros(1, bool)})
        other = Shield(PRM, variant="CV_none", config=ShieldConfig(assessment="truth"))
        other.reset(truth)
        assert not other.step(truth, (np.zeros(1), np.zeros(1))).f_aggressive.any()
    finally:
        del policies.ASSESSMENTS["pessimist"]
