"""Why the supervisor exists (issue 4, "what it must show" 3), on small samples.

``benchmarks/supervisor_ablation.py`` measures the same claims on thousands of scenarios per cell, and
``benchmarks/closed_loop_nn.py`` the network against its teacher; see docs/planners.md, "Closed-loop results".
Every run here is seeded; the paper's assumptions hold throughout (p_v = 0, ``a_x_N+1_d <= a_x_d``, and the
follower's type known to the supervisor — ``assessment="truth"`` — or F connected).
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.experiments.grid import Cell, run_cells
from safelane.planners import MLPPlanner, get_nominal
from safelane.planners.nn import HEADS, with_random_weights
from safelane.sim import SimConfig, simulate, simulate_batch
from sim_scenarios import mixed_campaign_batch

TRUTH = SimConfig(assessment="truth")
UNSUPERVISED = SimConfig(assessment="truth", supervised=False)
OUTCOMES = ["collision", "safety_violation", "leader_collision", "leader_violation"]


@pytest.fixture(scope="module")
def mlp() -> MLPPlanner:
    return get_nominal("mlp")


@pytest.fixture(scope="module")
def random_nets(mlp) -> list[MLPPlanner]:
    return [with_random_weights(mlp, np.random.default_rng(seed)) for seed in (0, 1)]


def l1_brakes_hard_without_v2x(samples: int, config: SimConfig, nominal):
    """No connected leader (N = 0): L1 itself brakes at 6 m/s² from t = 0 and tells nobody. The unsupervised
    network merges behind L1 and runs into it: 60 of these 60 scenarios, 954 of 1,000 in the benchmark's mixed
    traffic."""
    return simulate("CV_all", n_leaders=0, decel=6.0, samples=samples, seed=0, config=config, nominal=nominal).table


def mixed_scenarios(samples: int = 300, seed: int = 4):
    """N ∈ {0, 1, 3, 5, 10}, ``a_x_N+1_d ~ U[2, 8]`` per scenario, mixed follower types, 20 % human leaders."""
    return mixed_campaign_batch("CV_all", samples, np.random.default_rng(seed))


# ---------------------------------------------------------------- the network without the supervisor collides
def test_nn_without_supervisor_collides_where_l1_brakes_hard(mlp):
    table = l1_brakes_hard_without_v2x(60, UNSUPERVISED, mlp)
    assert table["collision"].sum() > 0
    # The same scenarios with the supervisor: no collision.
    assert not l1_brakes_hard_without_v2x(60, TRUTH, mlp)["collision"].any()


def test_nn_with_supervisor_never_collides(mlp):
    table = simulate_batch(mixed_scenarios(), seed=4, config=TRUTH, nominal=mlp).table
    assert not table[OUTCOMES].to_numpy().any()
    paper_cells = [Cell("CV_all", n, d) for n in (1, 3, 10) for d in (2.0, 4.0, 6.0)]
    table = run_cells(paper_cells, 20, seed=5, config=SimConfig(), nominal=mlp)
    assert not table["collision"].any()
    assert table["success"].mean() > 0.95


# ---------------------------------------------------------------- random weights: unsafe alone, safe supervised
def test_random_weights_are_the_default_architecture_and_seeded(mlp, random_nets):
    net = random_nets[0]
    np.testing.assert_array_equal(net.mean, mlp.mean)
    np.testing.assert_array_equal(net.std, mlp.std)
    assert net.bounds == mlp.bounds and net.activation == mlp.activation
    for head in HEADS:
        assert [w.shape for w, _ in net.layers[head]] == [w.shape for w, _ in mlp.layers[head]]
        assert not np.allclose(net.layers[head][0][0], mlp.layers[head][0][0])
    again = with_random_weights(mlp, np.random.default_rng(0))
    np.testing.assert_array_equal(again.layers["a_x"][0][0], net.layers["a_x"][0][0])
    assert not np.array_equal(random_nets[1].layers["a_x"][0][0], net.layers["a_x"][0][0])


def test_random_weights_ask_for_the_whole_action_range(random_nets):
    obs = simulate_batch(mixed_scenarios(200), seed=4, config=TRUTH, record_observations=True).observations
    a_x = np.concatenate([net(o, Params())[0] for net in random_nets for o in obs[::10]])
    assert a_x.min() < -6.0 and a_x.max() > 1.5


def test_random_weights_with_supervisor_never_collide_nor_violate(random_nets):
    batch = mixed_scenarios()
    for net in random_nets:
        table = simulate_batch(batch, seed=4, config=TRUTH, nominal=net).table
        assert not table[OUTCOMES].to_numpy().any()


def test_random_weights_without_supervisor_collide(random_nets):
    batch = mixed_scenarios()
    collisions = sum(
        int(simulate_batch(batch, seed=4, config=UNSUPERVISED, nominal=net).table["collision"].sum())
        for net in random_nets
    )
    assert collisions > 0
