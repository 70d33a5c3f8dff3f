"""Issue 31: what TrafficHooks.follower_wish does to a collaborative F behind a lane-changing ego, as the simulator
does it (its docstring said the wish was clipped to <= 0; the simulator never did, and the shield does not need it:
a collaborative F follows the ego responsibly, which is what the shield assumes and its monitor watches)."""

from __future__ import annotations

import numpy as np

from safelane import Params
from safelane.sim import SimConfig, simulate_batch
from safelane.sim.scenario import explicit_scenarios
from safelane.sim.traffic import TrafficHooks

PRM = Params()


def _run(f_x: float):
    batch = explicit_scenarios(ego=(0.0, 0.0, 30.0, 0.0), follower=(f_x, 30.0), leaders=([40.0, 80.0], [30.0, 30.0]),
                               decel_last=1.0, follower_connected=True, follower_aggressive=False)  # fmt: skip
    push = TrafficHooks(follower_wish=lambda view, prm: np.full(len(view.x), prm.a_x_a))
    return simulate_batch(batch, seed=0, config=SimConfig(horizon_s=1.5), traffic=push, trace=True)


def test_a_collaborative_followers_positive_wish_is_not_clipped_while_the_ego_changes_lanes():
    res = _run(-60.0)
    tr = res.trace
    changing = tr[(tr["ego_y"] > 0.0) & ~tr["completed"]]
    assert len(changing) >= 10
    accel = np.diff(np.concatenate([[30.0], tr["f_v"].to_numpy()])) / PRM.dt
    # Far behind the ego, F accelerates as it wishes (a_x_a), not at <= 0.
    np.testing.assert_allclose(accel[: len(changing)], PRM.a_x_a, atol=1e-9)
    assert not res.table["collision"].any() and not res.table["safety_violation"].any()


def test_close_behind_the_ego_responsible_following_still_holds_it_back():
    tr = _run(-8.0).trace
    accel = np.diff(np.concatenate([[30.0], tr["f_v"].to_numpy()])) / PRM.dt
    assert accel[0] < PRM.a_x_a  # the responsible filter (p_m to the ego against its a_x_d) binds
    gap = tr["ego_x"] - tr["f_x"]
    assert (gap >= PRM.p_m - 1e-6).all() or (tr["ego_y"] <= PRM.y_safe).all()
