"""The adversarial planners as data in the compiled closed loop (``planners/_fast_adversary.py``, the falsifier's
nominal planners): each planner's law against a hand-written formula, the table it becomes, and the loop against
the period-by-period path, bit for bit, on the falsifier's own batches (every kind, per-row parameters, traffic hooks
as data, the lane-gap recorder)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane import Params
from safelane.experiments import falsify_build as built
from safelane.experiments import falsify_space as space
from safelane.experiments.falsify import LaneGapRecorder
from safelane.planners import adversarial as adv
from safelane.planners.base import ExpertPlanner, Observation
from safelane.sim import SimConfig, _fused, simulate_batch
from test_fast_core import needs_numba

PRM = Params()


def _obs(rng, n: int) -> Observation:
    u = lambda lo, hi: rng.uniform(lo, hi, n)  # noqa: E731
    p_x = u(-20.0, 20.0)
    return Observation(
        p_x=p_x, p_y=u(-1.0, 5.0), v_x=u(0.0, 35.0), v_y=u(-1.5, 1.5), p_x_l=p_x + u(-5.0, 60.0), v_x_l=u(0.0, 35.0),
        p_x_f=p_x - u(-5.0, 60.0), v_x_f=u(0.0, 35.0), l1_plan=np.zeros((n, 1)), l1_connected=np.ones(n, bool),
        f_connected=np.ones(n, bool), completed=np.zeros(n, bool), t=1.7,
    )  # fmt: skip


def _clip(a_x, a_y):
    return np.minimum(np.maximum(a_x, -PRM.a_x_d), PRM.a_x_a), np.minimum(np.maximum(a_y, -PRM.a_y_m), PRM.a_y_m)


def test_each_adversary_is_its_law_written_by_hand():
    rng = np.random.default_rng(1)
    n = 400
    o = _obs(rng, n)
    k_p, k_v, off, om, ze = rng.uniform(0.1, 10, n), rng.uniform(0, 10, n), rng.uniform(-1, 3, n), \
        rng.uniform(0.3, 2, n), rng.uniform(0.05, 1.5, n)  # fmt: skip
    lat = om**2 * (PRM.lane_width - o.p_y) - 2 * ze * om * o.v_y
    got = adv.HugLeader(k_p, k_v, off, om, ze)(o, PRM)
    want = _clip(k_p * (o.p_x_l - PRM.p_m - off - o.p_x) + k_v * (o.v_x_l - o.v_x), lat)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    got = adv.HugFollower(k_p, k_v, off, om, ze)(o, PRM)
    want = _clip(k_p * (o.p_x_f + PRM.p_m + off - o.p_x) + k_v * (o.v_x_f - o.v_x), lat)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    period, ph_x, ph_y = rng.uniform(0.1, 3, n), rng.uniform(0, 1, n), rng.uniform(0, 1, n)
    amp_x, mean_x, amp_y, mean_y = rng.uniform(0, 6, n), rng.uniform(-6, 2.4, n), rng.uniform(0, 2.8, n), \
        rng.uniform(-0.5, 2.8, n)  # fmt: skip
    got = adv.Oscillating(period, ph_x, ph_y, amp_x, mean_x, amp_y, mean_y)(o, PRM)
    frac = lambda ph: np.array([(1.7 / p + f) - np.floor(1.7 / p + f) for p, f in zip(period, ph, strict=True)])  # noqa: E731
    sq = lambda ph: np.where(frac(ph) < 0.5, 1.0, -1.0)  # noqa: E731
    np.testing.assert_allclose(got, _clip(mean_x + amp_x * sq(ph_x), mean_y + amp_y * sq(ph_y)), rtol=1e-12)
    gain = rng.uniform(0.2, 1, n)
    got = adv.RecklessMerge(mean_x, gain)(o, PRM)
    side = [1.0 if d > 0 else -1.0 if d < 0 else 0.0 for d in PRM.lane_width - o.p_y]
    np.testing.assert_allclose(got, _clip(mean_x, gain * PRM.a_y_m * np.array(side)), rtol=1e-12)


def test_the_table_holds_each_rows_planner_and_refuses_others():
    n = 9
    choice = np.array([0, 1, 2, 3, 7, 0, 2, 3, 1])
    mix = adv.Mixture((adv.HugLeader(k_p=np.arange(n) + 1.0), adv.HugFollower(offset_m=2.0), adv.Oscillating(),
                       adv.RecklessMerge(a_x=-1.0, lateral_gain=0.5)), choice)  # fmt: skip
    kind, q = adv.adversary_table(mix, n)
    np.testing.assert_array_equal(kind, [0, 1, 2, 3, adv.ZERO, 0, 2, 3, 1])
    assert q[5, 0] == 6.0 and q[1, 2] == 2.0 and q[3, 0] == -1.0 and q[3, 1] == 0.5 and q[2, 0] == 1.0
    assert adv.adversary_table(ExpertPlanner(), n) is None
    assert adv.adversary_table(adv.Mixture((ExpertPlanner(),), np.zeros(n, int)), n) is None
    with pytest.raises(ValueError, match="k_p"):
        adv.adversary_table(adv.Mixture((adv.HugLeader(k_p=np.ones(3)),), np.zeros(n, int)), n)


def _falsifier_batch(world: str, rows: int, seed: int):
    """A falsifier batch of the rows inside the assumptions, with its planner and hooks (as ``falsify.evaluate``)."""
    spec = space.decode(np.random.default_rng(seed).uniform(size=(rows, space.dimension(PRM, world))), PRM, 0.0,
                        world)  # fmt: skip
    batch, ok = built.build(spec, PRM, profiles=True)
    keep = np.flatnonzero(ok)
    sub = dataclasses.replace(batch.take(keep), scenario_id=np.arange(keep.size, dtype=np.int64))
    return sub, space.take(spec, keep)


@pytest.mark.compiled
@needs_numba
@pytest.mark.parametrize("hooks", [True, False])
def test_the_loop_runs_the_adversaries_as_the_periods_do(monkeypatch, hooks):
    sub, spec = _falsifier_batch("paper", 400, 3)
    cfg = SimConfig(assessment="truth", horizon_s=6.0)
    planner = built.planner_for(spec, PRM)
    assert set(np.unique(adv.adversary_table(planner, len(sub))[0])) == {0, 1, 2, 3}
    runs, ratios = [], []
    for no_fused in ("", "1"):
        monkeypatch.setenv("SAFELANE_NO_FUSED", no_fused)
        recorder = LaneGapRecorder(sub, PRM)
        traffic = built.hooks_for(spec, PRM, recorder, k=sub.x.shape[1]) if hooks else None
        runs.append(simulate_batch(sub, 2, params=PRM, config=cfg, nominal=planner, traffic=traffic))
        ratios.append(recorder.min_ratio.copy())
    assert [r.engine for r in runs] == ["compiled loop", "period by period"]
    for col in runs[1].table:
        a, b = runs[0].table[col].to_numpy(), runs[1].table[col].to_numpy()
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), col
    np.testing.assert_array_equal(ratios[0], ratios[1])
    # the planners matter: the expert's run differs, and the adversaries bring the ego to the shield's limits
    monkeypatch.setenv("SAFELANE_NO_FUSED", "")
    expert = simulate_batch(sub, 2, params=PRM, config=cfg).table
    assert not expert["min_gap_leader_m"].equals(runs[0].table["min_gap_leader_m"])
    assert (runs[0].table["n_abort"] > 0).any() or (runs[0].table["n_hesitate"] > 0).any()


@pytest.mark.compiled
@needs_numba
def test_progress_and_blame_keep_per_row_planners_whole(monkeypatch):
    sub, spec = _falsifier_batch("paper", 200, 4)
    planner = built.planner_for(spec, PRM)
    monkeypatch.setattr(_fused, "PROGRESS_CHUNK", 16)
    cfg = SimConfig(assessment="truth", horizon_s=3.0)
    plain = simulate_batch(sub, 2, params=PRM, config=cfg, nominal=planner).table
    shown = simulate_batch(sub, 2, params=PRM, config=cfg, nominal=planner, progress=True).table
    assert plain.equals(shown)
    blamed = simulate_batch(sub, 2, params=PRM, config=cfg, nominal=planner, blame=True)
    assert blamed.engine == "period by period"
    assert blamed.table["collision"].equals(plain["collision"])
