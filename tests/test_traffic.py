"""Traffic-level co-simulation (safelane.traffic, docs/traffic.md): the network, the demand, the equipped vehicles'
batched shield, the measures and the sweep's determinism. Short runs at low demand keep it fast."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.traffic import measures
from safelane.traffic.demand import ACCEL_LANE, Demand, arrivals, lane_of, lane_y, net_file, routes_xml


def _libsumo():
    from safelane.integrations.sumo_world import libsumo_available

    if not libsumo_available():
        pytest.skip("libsumo is not installed: pip install 'safelane[sumo]'")


# -- pure parts
def test_arrivals_are_seeded_and_equipped_sets_nest_across_penetration():
    low, high = arrivals(Demand(p=0.25, seconds=600, warmup_s=60)), arrivals(Demand(p=0.75, seconds=600, warmup_s=60))
    assert [(t, r) for t, r, _ in low] == [(t, r) for t, r, _ in high]  # the same vehicles at every p
    eq_low, eq_high = np.array([e for *_, e in low]), np.array([e for *_, e in high])
    assert eq_low.sum() < eq_high.sum() and not (eq_low & ~eq_high).any()
    assert not any(e for *_, e in arrivals(Demand(p=0.0, seconds=600, warmup_s=60)))
    n = len(arrivals(Demand(p=0.0, main_vph=3600, ramp_vph=0, seconds=3600, warmup_s=60)))
    assert 3400 < n < 3800  # Poisson at 3600 veh/h
    assert routes_xml(Demand(p=1.0, seconds=100, warmup_s=10)).count('type="cav"') > 0


def test_lanes_are_counted_from_the_left():
    assert lane_of(lane_y(np.arange(4))).tolist() == [0, 1, 2, 3]
    assert lane_of([-1.75 - 1.6, -12.25]).tolist() == [0, ACCEL_LANE]


def test_blame_rear_unless_the_front_cut_in_within_the_safe_distance():
    crash = {"t": 100.0, "collider": "human.1", "victim": "cav.2", "type": "collision"}
    far_entry = {"t": 98.5, "vid": "cav.2", "follower": "human.1", "gap_m": 90.0, "v_follower": 30.0, "v_vid": 25.0}
    near_entry = {**far_entry, "gap_m": 5.0}
    old_entry = {**near_entry, "t": 90.0}
    other = {**near_entry, "follower": "human.9"}
    assert measures.blame([crash], [])[0]["responsible"] == "human.1"
    assert measures.blame([crash], [far_entry])[0]["rule"] == "rear"
    cut = measures.blame([crash], [near_entry])[0]
    assert (cut["responsible"], cut["rule"]) == ("cav.2", "cut-in")
    assert measures.blame([crash], [old_entry])[0]["responsible"] == "human.1"  # outside the window
    assert measures.blame([crash], [other])[0]["responsible"] == "human.1"  # cut in front of someone else
    # safe distance: v_r tau + v_r^2/(2 b_r) - v_f^2/(2 b_f), at least 0
    assert measures.safe_distance(30.0, 25.0) == pytest.approx(15 + 100 - 625 / 16)
    assert measures.safe_distance(0.0, 30.0) == 0.0


def test_ssm_parser_counts_conflicts_past_the_thresholds(tmp_path):
    path = tmp_path / "ssm.xml"
    path.write_text("""<SSMLog>
 <conflict begin="50" end="52" ego="cav.1" foe="human.2"><minTTC value="1.2"/><maxDRAC value="1.0"/><PET value="NA"/>
 </conflict>
 <conflict begin="60" end="62" ego="human.3" foe="human.2"><minTTC value="NA"/><maxDRAC value="4.0"/><PET value="3"/>
 </conflict>
 <conflict begin="70" end="72" ego="human.3" foe="human.4"><minTTC value="2.0"/><maxDRAC value="1.0"/><PET value="2"/>
 </conflict>
 <conflict begin="5" end="6" ego="human.3" foe="human.4"><minTTC value="0.5"/></conflict>
</SSMLog>""")
    rows = measures.ssm_conflicts(path, warmup_s=10.0)
    assert [(r["ego"], r["begin"]) for r in rows] == [("cav.1", 50.0), ("human.3", 60.0)]


def test_take_and_join_rows_keep_the_shield_state_aligned():
    from safelane import Params
    from safelane.shield import Situation, init
    from safelane.shield.rows import join_rows, take_rows

    prm = Params()
    s = Situation.from_arrays(t=0.0, ego=(np.array([0.0, 1.0, 2.0]), 0.0, 30.0, 0.0), follower=(-30.0, 30.0),
                              leaders=(np.array([[40.0, 80.0]]), np.array([[30.0, 30.0]])), n_connected=1,
                              params=prm)  # fmt: skip
    st = init(s, prm)
    back = join_rows(take_rows(st, np.array([0])), take_rows(st, np.array([1, 2])))
    np.testing.assert_array_equal(back.plan.ego_px, st.plan.ego_px)
    np.testing.assert_array_equal(take_rows(s, np.array([2])).ego_x, [2.0])


# -- with SUMO
def test_the_network_has_three_lanes_a_ramp_and_an_acceleration_lane_that_ends():
    _libsumo()
    import libsumo

    libsumo.start(["sumo", "-n", str(net_file()), "--no-step-log", "true"])
    try:
        lanes = {e: libsumo.edge.getLaneNumber(e) for e in ("in", "ramp", "merge", "out")}
        assert lanes == {"in": 3, "ramp": 1, "merge": 4, "out": 3}
        assert [c[0] for c in libsumo.lane.getLinks("ramp_0")] == ["merge_0"]
        assert not libsumo.lane.getLinks("merge_0")  # the acceleration lane ends: a mandatory change
        assert [c[0] for c in libsumo.lane.getLinks("merge_1")] == ["out_0"]
        assert libsumo.lane.getShape("merge_0")[0][1] == pytest.approx(lane_y(ACCEL_LANE))
    finally:
        libsumo.close()


def test_short_runs_give_the_measures_and_one_batched_shield_call_per_period(monkeypatch):
    _libsumo()
    from safelane.traffic import equipped, run

    calls, periods = [], []
    real_decide, real_period = equipped.decide, equipped.LaneChanges.period

    def counting_decide(pool, situation, *args):
        calls.append((len(periods), len(situation)))
        return real_decide(pool, situation, *args)

    def counting_period(self, fleet, t):
        periods.append(t)
        return real_period(self, fleet, t)

    monkeypatch.setattr(equipped, "decide", counting_decide)
    monkeypatch.setattr(equipped.LaneChanges, "period", counting_period)
    out = run.run_cell(Demand(p=1.0, main_vph=3000, ramp_vph=900, seconds=70, warmup_s=20, seed=1))
    row = out["row"]
    per_period = np.bincount([k for k, _ in calls])
    assert per_period.max() == 1  # never more than one shield call in a period
    assert max(n for _, n in calls) > 1  # and it is a batch
    assert row["shield_calls"] == len(calls) and row["shield_decisions"] == sum(n for _, n in calls)
    assert row["lc_started"] > 0 and row["lc_completed"] > 0 and row["inserted"] > 50
    assert 5 < row["mean_speed_mps"] < 40
    # aborted changes return to their own lanes within the deadline (they hovered at the boundary before)
    assert row["lc_aborted"] > 0 and row["lc_return_late"] == 0 and 0.0 < row["lc_return_max_s"] <= 8.0
    # this cell had a collision with an equipped vehicle responsible (a changer braking to 6 m/s for want of an F,
    # aborting in front of a vehicle SUMO had inserted behind it at 32 m/s): docs/traffic.md
    assert row["collisions_equipped_responsible"] == 0

    calls.clear()
    base = run.run_cell(Demand(p=0.0, main_vph=3000, ramp_vph=900, seconds=70, warmup_s=20, seed=1))["row"]
    assert not calls and base["lc_started"] == 0 and base["human_lane_changes"] > 0 and base["arrived"] > 0
    assert base["inserted"] == row["inserted"] or abs(base["inserted"] - row["inserted"]) < 10
    assert set(base) == set(run.CELL_COLUMNS)


def test_collisions_come_from_sumos_own_list():
    _libsumo()
    from safelane.traffic.world import TrafficWorld

    routes = """<routes><vType id="car" length="4.8" width="1.8" minGap="0"/>
    <route id="main" edges="in merge out"/>
    <vehicle id="human.front" type="car" route="main" depart="0" departLane="1" departPos="300" departSpeed="0"/>
    <vehicle id="cav.rear" type="car" route="main" depart="0" departLane="1" departPos="200" departSpeed="25"/>
    </routes>"""
    with TrafficWorld(Demand(p=0.0, seconds=30, warmup_s=1), routes=routes, ssm=False) as world:
        world.step()
        world.read()
        world.take("cav.rear")
        world.api.vehicle.setSpeedMode("human.front", 0)
        found = []
        for _ in range(100):
            world.api.vehicle.setSpeed("human.front", 0.0)
            world.api.vehicle.setSpeed("cav.rear", 25.0)
            world.step()
            found += world.collisions()
            if found:
                break
    assert found and (found[0]["collider"], found[0]["victim"]) == ("cav.rear", "human.front")
    assert measures.blame(found[:1], [])[0]["responsible"] == "cav.rear"


@pytest.fixture(scope="module")
def sweep_jobs_and_one_process():
    """A short sweep's jobs and its tables on one process (the reference of the other backends)."""
    _libsumo()
    from safelane.traffic.run import cells, sweep

    jobs = cells([0.0, 0.5], [2500], seconds=40, warmup_s=10, seed=3)
    one, coll_one, _ = sweep(jobs, "process", 1)
    return jobs, one.to_csv(index=False), coll_one.to_csv(index=False)


def test_the_sweep_gives_the_same_tables_on_one_and_two_processes(sweep_jobs_and_one_process):
    from safelane.traffic.run import sweep

    jobs, one, coll_one = sweep_jobs_and_one_process
    two, coll_two, _ = sweep(jobs, "process", 2)
    assert one == two.to_csv(index=False)
    assert coll_one == coll_two.to_csv(index=False)
    assert two["p"].tolist() == [0.0, 0.5]


def test_the_sweep_gives_the_same_tables_on_ray(sweep_jobs_and_one_process):
    from safelane.parallel import Backend, ray_available, ray_session
    from safelane.traffic.run import sweep

    if not ray_available():
        pytest.skip("ray is not installed: pip install 'safelane[ray]'")
    jobs, one, coll_one = sweep_jobs_and_one_process
    with ray_session(num_cpus=1):  # a local instance (or the cluster $RAY_ADDRESS names); one task at a time
        table, coll, _ = sweep(jobs, Backend("ray", 2))
    assert one == table.to_csv(index=False)
    assert coll_one == coll.to_csv(index=False)


def _braking_run(limits: dict[str, float] | None, steps: int = 90, go_step: int = 40):
    """Two equipped vehicles driven by SUMO: ``cav.hard`` closes on a standing vehicle in its lane (SUMO wants to
    brake hard) that drives off at 30 m/s from step ``go_step`` (then SUMO wants to brake no more), ``cav.mild``
    follows a faster vehicle (SUMO never wants to brake). With ``limits`` every step
    limits their braking (``TrafficWorld.limit_braking``). Per step: SUMO's speeds after the step (its own, read
    back with ``getSpeed``), lane positions, SUMO's wish where it was limited, and each vehicle's ``decel``."""
    from safelane.traffic.world import TrafficWorld

    routes = """<routes><vType id="car" length="4.8" width="1.8" minGap="2.5" accel="2.6" decel="4.5"
    emergencyDecel="8" sigma="0" tau="1" speedFactor="1"/>
    <route id="main" edges="in merge out"/>
    <vehicle id="human.stop" type="car" route="main" depart="0" departLane="1" departPos="300" departSpeed="0"/>
    <vehicle id="cav.hard" type="car" route="main" depart="0" departLane="1" departPos="150" departSpeed="25"/>
    <vehicle id="human.fast" type="car" route="main" depart="0" departLane="2" departPos="250" departSpeed="33"/>
    <vehicle id="cav.mild" type="car" route="main" depart="0" departLane="2" departPos="200" departSpeed="25"/>
    </routes>"""
    vids = ("cav.hard", "cav.mild")
    out = {"v": [], "x": [], "wish": [], "decel": []}
    with TrafficWorld(Demand(p=0.0, seconds=60, warmup_s=1), routes=routes, ssm=False) as world:
        veh = world.api.vehicle
        world.step()
        world.read()
        for vid in ("human.stop", "human.fast"):
            veh.setLaneChangeMode(vid, 0)
        veh.setSpeedMode("human.stop", 0)
        for k in range(steps):
            veh.setSpeed("human.stop", 0.0 if k < go_step else 30.0)
            if limits is not None:
                world.limit_braking(list(limits), list(limits.values()))
            world.step()
            world.read()
            out["v"].append([veh.getSpeed(v) for v in vids])
            out["x"].append([veh.getLanePosition(v) for v in vids])
            out["wish"].append([world.wished.get(v, np.nan) for v in vids])
            out["decel"].append([veh.getDecel(v) for v in vids])
            world.wished.clear()
        lag = world.max_lag_m
    return {**{k: np.array(v) for k, v in out.items()}, "max_lag_m": lag}


def test_a_connected_leader_brakes_at_most_at_its_bound_and_otherwise_as_sumo_wants():
    _libsumo()
    dt, bound = 0.1, 1.0
    free = _braking_run(None)
    lim = _braking_run({"cav.hard": bound, "cav.mild": 0.5})
    # the vehicle whose wish is milder than its bound drives exactly as without any limit (the removed cap of
    # SUMO's decel made Krauss plan with 0.5 m/s²: it ended at 20.5 m/s here instead of 33.8)
    np.testing.assert_array_equal(lim["v"][:, 1], free["v"][:, 1])
    np.testing.assert_array_equal(lim["x"][:, 1], free["x"][:, 1])
    assert (lim["decel"] == 4.5).all()  # Krauss plans with the human decel throughout
    assert (np.diff(free["v"][:, 0]) < -3.0 * dt).any()  # unlimited, SUMO brakes at > 3 m/s²
    prev, v, wish = lim["v"][:-1, 0], lim["v"][1:, 0], lim["wish"][1:, 0]
    wish = np.where(np.isnan(wish), v, wish)  # no entry: SUMO's choice was not changed
    floor = prev - bound * dt
    hard = wish < floor - 1e-9
    assert hard.sum() > 10 and (hard[:-1] & ~hard[1:]).any()  # SUMO wanted to brake harder than the bound ...
    np.testing.assert_allclose(v[hard], floor[hard], atol=1e-9)  # ... and it braked exactly at the bound
    assert (v[~hard] >= floor[~hard] - 1e-9).all()  # elsewhere SUMO's own choice, milder, stands
    first = np.flatnonzero(hard)[0] + 1
    np.testing.assert_array_equal(lim["v"][:first, 0], free["v"][:first, 0])  # untouched before
    # SUMO moved it with its own choice (the limit lifts the speed after the step): the position trails the
    # limited motion by (floor - wish) dt / 2 per limited step, the lag the world reports
    dx = np.diff(lim["x"][:, 0])
    np.testing.assert_allclose(dx[hard], 0.5 * (prev[hard] + wish[hard]) * dt, atol=1e-6)
    assert lim["max_lag_m"] == pytest.approx(0.5 * dt * (floor - wish)[hard].sum())
