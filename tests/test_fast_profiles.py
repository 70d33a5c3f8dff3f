"""L(N+1)'s braking profiles and the traffic hooks as data (:class:`~safelane.sim.traffic.WaveHooks`) in the compiled
closed loop (``sim/_fast_loop._period``): the same table, bit for bit, as the period-by-period path with its part
kernels (``SAFELANE_NO_FUSED=1``) and as the NumPy path (``SAFELANE_NO_NUMBA=1``) — on batches where the profile's
switches inside a period bring the switching vehicle near the ego and near the leader behind it (the checks' two
segment pairs run, counted on the NumPy path), and where the profile and the hooks change the outcome."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.experiments import falsify as fz
from safelane.experiments import falsify_space as space
from safelane.sim import SimConfig, _fused, checks, concat, paper_scenarios, simulate_batch
from safelane.sim.traffic import with_last_profile
from test_fast_core import needs_numba

pytestmark = [pytest.mark.compiled, needs_numba]

PRM = Params()
PATHS = {"compiled": {}, "period by period": {"SAFELANE_NO_FUSED": "1"}, "numpy": {"SAFELANE_NO_NUMBA": "1"}}


def _env(monkeypatch, path: str) -> None:
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    for name, value in PATHS[path].items():
        monkeypatch.setenv(name, value)


def _count_switched_pairs(monkeypatch) -> dict:
    """Count, on the NumPy path, the near pairs with a switching vehicle: the ego's (the general path) and the lane's
    (their exact minimum over both motions)."""
    seen = {"ego": 0, "lane": 0}
    general, gap = checks.general_pairs, checks.gap_extrema

    def general_pairs(r, c, mask, planned, lon, lat, plan, others, *rest):
        if others.switch is not None:
            seen["ego"] += int(others.switch.mask[r[mask], c[mask]].sum())
        return general(r, c, mask, planned, lon, lat, plan, others, *rest)

    def gap_extrema(behind, ahead):
        seen["lane"] += len(behind.t)
        return gap(behind, ahead)

    monkeypatch.setattr(checks, "general_pairs", general_pairs)
    monkeypatch.setattr(checks, "gap_extrema", gap_extrema)
    return seen


def _profiled(seed: int):
    """N = 0..3 (N = 0: L1 is L(N+1)), ego and F close, L(N+1) switching every few periods, inside periods and on
    their boundaries, between hard braking and accelerating."""
    rng = np.random.default_rng(seed)
    variants = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
    batch = concat([paper_scenarios(v, n, 5.0, 40, rng, first_id=100 * (4 * n + k))
                    for n in range(4) for k, v in enumerate(variants)])  # fmt: skip
    size = len(batch)
    steps = rng.integers(2, 12, size=(size, 5)) * PRM.dt + rng.choice([0.0, 0.03, 0.061, 1e-12], size=(size, 5))
    times = np.concatenate([np.zeros((size, 1)), np.cumsum(steps, 1)], 1)
    accels = np.where(rng.uniform(size=(size, 6)) < 0.5, -PRM.others_decel, rng.uniform(-PRM.a_x_d, PRM.a_x_a,
                                                                                          (size, 6)))  # fmt: skip
    return batch, with_last_profile(batch, times, accels, PRM)


@pytest.mark.parametrize("seed", [0, 1])
def test_profiles_in_the_compiled_loop_give_the_numpy_paths_bits(monkeypatch, seed):
    plain, batch = _profiled(seed)
    tables, engines = {}, {}
    seen = {}
    for path in PATHS:
        _env(monkeypatch, path)
        if path == "numpy":
            seen = _count_switched_pairs(monkeypatch)
        result = simulate_batch(batch, seed=3, params=PRM)
        tables[path], engines[path] = result.table, result.engine
    assert engines["compiled"] == "compiled loop"
    assert seen["ego"] > 0 and seen["lane"] > 0  # the two-segment pairs ran
    for path in ("period by period", "numpy"):
        assert tables["compiled"].equals(tables[path]), path
    _env(monkeypatch, "compiled")
    assert not simulate_batch(plain, seed=3, params=PRM).table.equals(tables["compiled"])  # the profile matters


def _round(world: str, rows: int, seed: int) -> list[dict]:
    dim = space.dimension(PRM, world)
    rng = [np.random.default_rng([seed, m]) for m in range(3)]
    return [space.decode(rng[0].uniform(size=(rows, dim)), PRM, 0.0, world),
            space.decode(fz.CrossEntropy(dim).ask(rng[1], rows), PRM, 0.0, world),
            space.knife_specs(rng[2], rows, PRM, 0.0, world)]  # fmt: skip


def test_the_falsifiers_hooks_planners_and_profiles_compiled_give_the_numpy_paths_bits(monkeypatch):
    specs = _round("paper", 150, 11)
    setting = fz.Setting(sim=SimConfig(assessment="truth", horizon_s=5.0)).resolved()
    engines = []
    real = fz.simulate_batch

    def recording(*args, **kwargs):
        result = real(*args, **kwargs)
        engines.append(result.engine)
        return result

    monkeypatch.setattr(fz, "hooks_live", lambda: True)  # (the wrapper hides simulate_batch's signature)
    monkeypatch.setattr(fz, "simulate_batch", recording)
    outcomes = {}
    for path in PATHS:
        _env(monkeypatch, path)
        outcomes[path] = fz.evaluate_round(specs, setting)[0]
    # the same round on the compiled period, the adversaries between its periods (the loop refused by its size)
    _env(monkeypatch, "compiled")
    monkeypatch.setattr(_fused, "FUSED_MIN_ROWS", 10**9)
    outcomes["compiled period"] = fz.evaluate_round(specs, setting)[0]
    assert engines == ["compiled loop", "period by period", "period by period", "compiled period"]
    for path in ("period by period", "numpy", "compiled period"):
        for mine, theirs in zip(outcomes["compiled"], outcomes[path], strict=True):
            assert mine.equals(theirs), path
    assert all(np.isfinite(o["lane_ratio"]).any() for o in outcomes["compiled"])  # the lane-gap sample ran
    # The hooks and the profiles change the outcomes (the compiled period runs both).
    _env(monkeypatch, "compiled")
    for off in (dict(use_hooks=False), dict(use_profiles=False)):
        other = fz.evaluate_round(specs, fz.Setting(sim=setting.sim, **off).resolved())[0]
        assert not all(a.equals(b) for a, b in zip(other, outcomes["compiled"], strict=True))
