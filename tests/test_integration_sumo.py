"""The shield in SUMO (safelane.integrations.sumo): SUMO's own collision list is the referee.

libsumo allows one simulation per process, so every test here shares one :class:`SumoRunner` (module fixture).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("libsumo", reason="libsumo is not installed: pip install 'safelane[sumo]' (make install does)")

from safelane import Params
from safelane.integrations import sumo
from safelane.integrations.sumo_world import (
    SumoWorld,
    VehicleSpec,
    braking_parity,
    centre_to_front,
    front_to_centre,
    routes_xml,
)


@pytest.fixture(scope="module")
def runner():
    with sumo.SumoRunner(policy=sumo.reckless) as r:  # the stress test: always merge at full authority
        yield r


def test_settings_read_back_from_sumo(runner):
    runner.run(sumo.sumo_scenarios(1, 4.0, 1, seed=3)[0])
    s = runner.settings()
    assert s["step_length_s"] == pytest.approx(Params().dt)
    assert s["ballistic"] == "true"
    assert s["collision_action"] == "warn"
    assert s["collision_mingap_factor"] == 0.0
    assert s["lateral_resolution_m"] > 0.0  # the sublane model is on
    assert s["lane_width_m"] == [Params().lane_width] * 2
    assert s["lane_centre_y_m"][1] - s["lane_centre_y_m"][0] == pytest.approx(Params().lane_width)


def test_front_bumper_conversion(runner):
    prm = Params()
    assert float(front_to_centre(centre_to_front(12.5, prm.vehicle_length), prm.vehicle_length)) == 12.5
    assert 'departPos="102.4"' in routes_xml([VehicleSpec("a", 0, 100.0, 30.0)], prm)
    world = runner.world
    world.load([VehicleSpec("a", 0, 100.0, 30.0), VehicleSpec("b", 1, 150.0, 20.0)])
    api = world.api.vehicle
    assert api.getLanePosition("a") == pytest.approx(100.0 + prm.vehicle_length / 2, abs=1e-9)  # SUMO: front bumper
    lane = world.lane(1)
    assert lane.ids == ("b",) and lane.x[0] == pytest.approx(150.0, abs=1e-9)  # read back as the centre
    world.place("a", 110.0, world.lane_y[0] + 1.0, 30.0)  # the ego's way: centre and lateral offset, moveToXY
    world.step()
    assert world.position("a") == pytest.approx((110.0, world.lane_y[0] + 1.0), abs=1e-9)


def test_braking_parity_with_point_mass(runner):
    """A vehicle braking at constant deceleration: SUMO's ballistic positions equal ours to 1e-9 m while it moves;
    the stopping step overshoots by at most decel·dt²/8 (1 cm at 8 m/s²)."""
    for v0, decel in ((30.0, 8.0), (25.0, 6.0), (30.3, 7.7)):
        r = braking_parity(runner.world, v0, decel)
        assert r["max_pos_err_moving_m"] < 1e-9
        assert r["max_speed_err_mps"] < 1e-9
        assert r["max_pos_err_stopped_m"] <= r["stop_bound_m"] + 1e-9


def test_one_simulation_per_process(runner):
    with pytest.raises(RuntimeError, match="one per process"):
        SumoWorld()


def test_own_lane_leaders_fill():
    x, v = sumo.own_lane_leaders(10.0, np.array([5.0, 30.0, 60.0]), np.array([1.0, 2.0, 3.0]))
    assert x.tolist() == [[30.0]] and v.tolist() == [[2.0]]
    x, v = sumo.own_lane_leaders(10.0, np.array([5.0]), np.array([1.0]))
    assert np.isposinf(x[0, 0])


def _scenarios():
    out = []
    for j, a in enumerate((4.0, 6.0, 8.0)):
        out += sumo.sumo_scenarios(3, a, 6, seed=11, own_share=0.5, first_id=100 * j)
        out += sumo.sumo_scenarios(1, a, 2, seed=12, first_id=100 * j + 50)
    return out


def test_shielded_episodes_never_collide_by_sumos_list(runner):
    table = runner.run_many(_scenarios(), shielded=True)
    assert len(table) == 24
    assert not table.collided.any(), table[table.collided]
    assert not table.geometric_overlap.any()
    assert table.success.mean() > 0.3  # the shield does not win by never merging
    assert (table.steps == 100).all()


def test_reckless_without_shield_collides(runner):
    """The same scenarios without the shield: the reckless policy hits L1, and SUMO's list says so."""
    table = runner.run_many(_scenarios(), shielded=False)
    assert table.collided.mean() > 0.5
    hits = table[table.collided]
    assert set(hits.collider) == {"ego"} and set(hits.lane) == {"road_1"}


def test_v2x_loss_and_sumo_traffic_run(runner):
    sc = sumo.sumo_scenarios(3, 6.0, 2, seed=5)
    lossy = sumo.SumoRunner(traffic="sumo", v2x_loss=0.5, v2x_latency_periods=1, world=runner.world,
                            policy=sumo.reckless)  # one SUMO
    res = lossy.run(sc[0])
    assert res.v2x_sent > 0 and 0 < res.v2x_lost < res.v2x_sent
    assert res.steps > 0


def test_delay_and_sensing_bounds_in_sumo(runner):
    """Issue 17 in SUMO: the ego executes each command 0.2 s late (the runner's actuator) and the shield takes the
    worst case over SensingBounds; it accounts for both and SUMO's list stays empty. The paper's shield under the
    same host delay (it does not know of it) collides — so the test can fail."""
    from safelane.shield import SensingBounds, ShieldConfig

    scenarios = sumo.sumo_scenarios(3, 6.0, 8, seed=3, own_share=0.5)
    extended = sumo.SumoRunner(config=ShieldConfig(actuation_delay_s=0.2), sensing=SensingBounds(), world=runner.world,
                               policy=sumo.reckless)
    table = extended.run_many(scenarios)
    assert table.collided.sum() == 0 and table.success.mean() > 0.3
    paper = sumo.SumoRunner(config=ShieldConfig(own_lane=False, sensing=False), world=runner.world,
                            policy=sumo.reckless)
    paper.delay_periods = 2  # the host delays by 0.2 s; this shield assumes instant actuation
    assert paper.run_many(scenarios).collided.sum() > 0


def test_reckless_collisions_are_blamed_on_the_ego(runner):
    """The blame rule (safelane.blame) on SUMO's own list: the unshielded reckless ego merges into the target lane
    without RSS's safe distance, so each of its collisions is the ego's, by the lateral clause; and the row says so."""
    res = [runner.run(sc, shielded=False) for sc in _scenarios()[:6]]
    hits = [c for r in res for c in r.collisions if c["collider"] == "ego"]
    assert hits, "no collision: the scenarios are wrong"
    assert {(c["responsible"], c["blame"], c["blame_clause"]) for c in hits} == {("ego", "collider", "lateral")}
    assert all(c["blame_t"] < c["t"] for c in hits)
    assert {r.collision_blame for r in res if r.collided} == {"ego"}
    assert {r.results_row("reckless")["collision_blame"] for r in res} <= {"ego", ""}
