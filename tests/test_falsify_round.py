"""The falsifier's round (its methods' batches simulated as one batch) gives each batch's outcomes as simulating it
alone does, bit for bit; the traffic hooks made once per run give the numbers of the formula evaluated per period."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.experiments import falsify_build as built
from safelane.experiments import falsify_space as space
from safelane.experiments.falsify import CrossEntropy, Setting, evaluate, evaluate_round
from safelane.planners.adversarial import square_wave
from safelane.sim import SimConfig
from safelane.sim.traffic import TrafficView

PRM = Params()


def _round(world: str, rows: int, seed: int, brake_starts=(0.0, 0.0, 0.0)) -> list[dict]:
    dim = space.dimension(PRM, world)
    rng = [np.random.default_rng([seed, m]) for m in range(3)]
    return [
        space.decode(rng[0].uniform(size=(rows, dim)), PRM, brake_starts[0], world),
        space.decode(CrossEntropy(dim).ask(rng[1], rows), PRM, brake_starts[1], world),
        space.knife_specs(rng[2], rows, PRM, brake_starts[2], world),
    ]


@pytest.mark.parametrize(
    ("world", "setting", "brake_starts"),
    [
        ("paper", Setting(sim=SimConfig(assessment="truth", horizon_s=4.0)), (0.0, 0.0, 0.0)),
        # Sudden braking (no profiles) from one instant per batch: the round holds several start groups.
        ("paper", Setting(sim=SimConfig(assessment="truth", horizon_s=4.0), use_profiles=False), (0.0, 0.7, 1.234)),
    ],
)
def test_a_round_gives_each_batch_its_own_outcomes(world, setting, brake_starts):
    specs = _round(world, 160, 5, brake_starts)
    setting = setting.resolved()
    outcomes, kept = evaluate_round(specs, setting)
    for spec, outcome, rows in zip(specs, outcomes, kept, strict=True):
        alone, alone_kept = evaluate(spec, setting)
        assert len(alone) > 0
        assert outcome.equals(alone.reset_index(drop=True))
        assert rows.keys() == alone_kept.keys()
        for key in rows:
            np.testing.assert_array_equal(rows[key], alone_kept[key])


def test_a_realistic_round_gives_each_batch_its_own_outcomes():
    sim = SimConfig(assessment="truth", horizon_s=2.0, own_lane=True, sensing_error=True, sensing_edge_share=0.5)
    setting = Setting(sim=sim, world="realistic").resolved()
    specs = _round("realistic", 64, 9)
    outcomes, _ = evaluate_round(specs, setting)
    for spec, outcome in zip(specs, outcomes, strict=True):
        assert outcome.equals(evaluate(spec, setting)[0].reset_index(drop=True))


def test_leader_hook_columns_made_once_give_the_per_period_formula():
    spec = _round("paper", 40, 2)[2]
    k = int(spec["n"].max()) + 2
    hooks = built.hooks_for(spec, PRM)
    ids = np.arange(40)[::-1].copy()  # any order of the scenario ids
    x = np.cumsum(np.ones((40, k)), 1)
    for t in (0.0, 0.1, 0.30000000000000004, 2.7):
        view = TrafficView(t=t, scenario_id=ids, x=x, v=x, n_connected=spec["n"][ids], ego_x=x[:, 0], ego_y=x[:, 0],
                           ego_vx=x[:, 0], ego_vy=x[:, 0], completed=np.zeros(40, bool),
                           follower_aggressive=np.zeros(40, bool))  # fmt: skip
        # The formula as it was evaluated every period before the columns were made once.
        pd_ = built._leaders(spec["promise_decel"][ids], k)
        pa = built._leaders(spec["promise_accel"][ids], k)
        hi, lo = built._leaders(spec["task_hi"][ids], k), built._leaders(spec["task_lo"][ids], k)
        phase = spec["task_phase"][ids][:, None] + 0.37 * np.arange(k)[None, :]
        up = square_wave(t, spec["task_period_s"][ids][:, None], phase) > 0
        want = -pd_ + np.where(up, hi, lo) * (pd_ + pa)
        np.testing.assert_array_equal(hooks.leader_task(view, PRM), want)
