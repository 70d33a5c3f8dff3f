"""The compiled ego checks (:mod:`safelane.sim._fast_checks`, numba) against ``checks.ego_checks``' NumPy path.

The kernel takes the near-pair filter, the far pairs' gaps and the two common near-pair kinds; the general pairs (an
ego on its evasion plan, or one stopping while it crosses a level) go back to NumPy's exact path. The closed loop
must give the same per-scenario table — collisions, violations, minimum gaps to F and L1 — with and without it: with
the shield (aborts: plan rows), without it (collisions), in the realistic world (own lane, sensing error, delays),
and with L(N+1) profiles that switch inside a period (the NumPy path throughout)."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.sim import SimConfig, checks, concat, paper_scenarios, simulate_batch
from safelane.sim.preset import load_preset
from test_fast_core import needs_numba, period_by_period  # noqa: F401 (a fixture)

pytestmark = [pytest.mark.compiled, pytest.mark.usefixtures("period_by_period")]



def _tables(monkeypatch, batch, cfg, params=None, traffic=None):
    """``(kernel's table, NumPy path's table, kernel calls with the kernel, kernel calls with the switch)``."""
    from safelane.sim import _fast_checks

    calls = []
    real = _fast_checks.ego_checks
    monkeypatch.setattr(_fast_checks, "ego_checks", lambda *a: calls.append(1) or real(*a))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = simulate_batch(batch, seed=2, config=cfg, params=params, traffic=traffic).table
    with_kernel = len(calls)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = simulate_batch(batch, seed=2, config=cfg, params=params, traffic=traffic).table
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    return fast, reference, with_kernel, len(calls) - with_kernel


def _batch(n_leaders, decel, per_variant=150, p_v=0.0):
    variants = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
    return concat([paper_scenarios(v, n_leaders, decel, per_variant, np.random.default_rng(10 * n_leaders + k),
                                   first_id=1000 * k, p_v=p_v) for k, v in enumerate(variants)])  # fmt: skip


@needs_numba
@pytest.mark.parametrize(
    "case",
    ["shield", "shield, violations, F ignores the ego", "paper-faithful", "unsupervised", "realistic"],
)
def test_the_closed_loop_gives_the_same_table_with_and_without_the_kernel(monkeypatch, case):
    params = None
    batch = _batch(1, 5.0) if case in ("unsupervised", "paper-faithful") else _batch(3, 6.0, p_v=0.05)
    cfg = {
        "shield": SimConfig(),
        "shield, violations, F ignores the ego": SimConfig(follower_ignores_ego=True),
        "paper-faithful": SimConfig(completion="paper_evasion", leader_rule="reactive", monitor=False),
        "unsupervised": SimConfig(supervised=False),
    }.get(case)
    if case == "realistic":
        preset = load_preset("realistic")
        cfg, params = preset.sim, preset.params
    fast, reference, calls, with_switch = _tables(monkeypatch, batch, cfg, params)
    assert calls > 50 and with_switch == 0  # the kernel ran (nearly) every period, and never with the switch
    different = [c for c in reference.columns if not fast[c].equals(reference[c])]
    assert not different, different
    if case == "unsupervised":  # collisions and p_m violations: the pair extrema decide them
        assert reference["collision"].sum() > 20 and reference["safety_violation"].sum() > reference["collision"].sum()
    if case.startswith("shield"):  # aborts: rows on their evasion plans take the general path
        assert reference["n_abort"].sum() > 100
    assert np.isfinite(reference["min_gap_follower_m"]).any() and np.isfinite(reference["min_gap_leader_m"]).any()


@needs_numba
def test_profiles_that_switch_inside_a_period_keep_the_numpy_path(monkeypatch):
    from safelane.sim.traffic import with_last_profile

    batch = _batch(3, 5.0, per_variant=40)
    n = len(batch)
    times = np.tile([0.0, 1.05, 2.57], (n, 1))  # switches off the period grid
    accels = np.tile([0.0, -6.0, 1.0], (n, 1))
    profiled = with_last_profile(batch, times, accels)
    fast, reference, calls, with_switch = _tables(monkeypatch, profiled, SimConfig())
    assert fast.equals(reference)
    assert 0 < calls < 100 and with_switch == 0  # not in the periods with a switch (those take the NumPy path)


@needs_numba
@pytest.mark.parametrize("name", ["ego_checks", "lane_checks"])
def test_the_kernels_run_from_their_threshold_on(monkeypatch, name):
    from safelane.sim import _fast_checks

    calls = []
    real = getattr(_fast_checks, name)
    monkeypatch.setattr(_fast_checks, name, lambda *a: calls.append(1) or real(*a))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    for rows in (checks.FAST_MIN_ROWS - 1, checks.FAST_MIN_ROWS):
        batch = paper_scenarios("CV_all", 3, 5.0, rows, np.random.default_rng(rows))
        before = len(calls)
        simulate_batch(batch, seed=0, config=SimConfig())
        assert (len(calls) > before) == (rows >= checks.FAST_MIN_ROWS), rows


def _pairs(rng, bsz: int, k: int):
    """``ego_checks``' inputs for ``bsz`` random scenarios of ``k`` target-lane vehicles near the ego: lateral
    positions and speeds that cross the conflict and overlap levels inside the period, gaps at and just inside
    ``p_m`` and the vehicle length, equal speeds, vehicles stopping inside the period."""
    from types import SimpleNamespace

    from safelane import Params
    from safelane.sim.kinematics import Fleet, Motion

    prm = Params()
    dt = prm.dt
    conflict, overlap = prm.y_safe + 1e-9, prm.lane_width - prm.vehicle_width
    pick = lambda p, shape=(bsz, k): rng.random(shape) < p  # noqa: E731
    ex, evx = rng.uniform(-5.0, 5.0, bsz), rng.uniform(0.0, 30.0, bsz)
    ey = rng.choice([conflict, overlap, 0.5, 1.2, 2.5], bsz) + rng.uniform(-0.1, 0.1, bsz)
    evy, a_y = rng.uniform(-1.5, 1.5, bsz), rng.uniform(-prm.a_y_m, prm.a_y_m, bsz)
    a_x = np.where(rng.random(bsz) < 0.3, -prm.a_x_d, rng.uniform(-prm.a_x_d, prm.a_x_a, bsz))
    evx = np.where(rng.random(bsz) < 0.2, rng.uniform(0.0, 0.4, bsz), evx)  # the ego stops inside the period
    sign = np.where(np.arange(k)[None, :] == 0, -1.0, 1.0)
    gap = np.where(
        pick(0.3), prm.p_m - 5e-10, np.where(pick(0.2), prm.vehicle_length * 0.9, rng.uniform(0, 15, (bsz, k)))
    )
    x = ex[:, None] + sign * gap
    v = np.where(pick(0.3), evx[:, None], rng.uniform(0.0, 30.0, (bsz, k)))
    v = np.where(pick(0.2), rng.uniform(0.0, 0.4, (bsz, k)), v)  # stopping inside the period
    acc = np.where(pick(0.5), -prm.a_x_d, rng.uniform(-prm.a_x_d, prm.a_x_a, (bsz, k)))
    x, v, acc = (np.asfortranarray(a) for a in (x, v, acc))
    s = SimpleNamespace(x=x, v=v, ego=(ex, ey, evx, evy), min_gap_f=np.full(bsz, np.inf),
                        min_gap_l1=rng.uniform(5.0, 50.0, bsz))  # fmt: skip
    b = SimpleNamespace(valid=np.asfortranarray(pick(0.9)))
    lon, lat = Motion.constant(ex, evx, a_x, dt), Motion.free(ey, evy, a_y, dt)
    return (b, prm, s, lon, lat, Fleet.constant(x, v, acc, dt), conflict, overlap)


@needs_numba
@pytest.mark.parametrize("k", [2, 5])
def test_the_kernel_gives_the_numpy_paths_bits_on_pairs_at_the_edges(monkeypatch, k):
    args = _pairs(np.random.default_rng(k), 20_000, k)
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = checks.ego_checks(*args)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = checks.ego_checks(*args)
    for name, a, r in zip(("collided", "violated", "min_gap_f", "min_gap_l1"), fast, reference, strict=True):
        same = (a == r) | (np.isnan(a) & np.isnan(r)) if a.dtype.kind == "f" else a == r
        assert same.all(), f"{name} differs at {np.flatnonzero(~same)[:5]}"
    collided, violated, gap_f, gap_l1 = reference
    assert 0 < collided.sum() < violated.sum() < len(collided)
    assert np.isfinite(gap_f).sum() > 1000 and (gap_l1 < 5.0).sum() > 1000


@needs_numba
def test_the_lane_kernel_gives_the_numpy_paths_bits(monkeypatch):
    """``lane_checks`` on 20,000 synthetic chains: gaps at, just inside and beyond the margins (``p_m`` and
    ``p_m_human``) and the vehicle length, vehicles at rest all period, stopping inside it, at equal speeds, invalid
    slots — with and without the kernel."""
    from types import SimpleNamespace

    from safelane import Params
    from safelane.sim.kinematics import Fleet

    prm = Params()
    rng = np.random.default_rng(17)
    bsz, k = 20_000, 6
    pick = lambda p: rng.random((bsz, k)) < p  # noqa: E731
    human = pick(0.3)
    margin = np.where(human, prm.p_m_human, prm.p_m)
    gaps = rng.uniform(0.0, 25.0, (bsz, k))
    gaps = np.where(pick(0.2), margin - rng.choice([0.0, 5e-10, 0.3], (bsz, k)), gaps)
    gaps = np.where(pick(0.05), prm.vehicle_length * rng.uniform(0.5, 1.0, (bsz, k)), gaps)
    x = np.cumsum(gaps, axis=1)
    v = np.where(pick(0.2), 0.0, rng.uniform(0.0, 30.0, (bsz, k)))
    v = np.where(pick(0.2), rng.uniform(0.0, 0.4, (bsz, k)), v)  # stopping inside the period
    v[:, 1:] = np.where(pick(0.2)[:, 1:], v[:, :-1], v[:, 1:])  # equal speeds
    acc = np.where(pick(0.4), -prm.a_x_d, np.where(pick(0.2), 0.0, rng.uniform(-prm.a_x_d, prm.a_x_a, (bsz, k))))
    fleet = Fleet.constant(*(np.asfortranarray(a) for a in (x, v, acc)), prm.dt)
    b = SimpleNamespace(valid=np.asfortranarray(pick(0.95)), human=np.asfortranarray(human))
    calls = []
    from safelane.sim import _fast_checks

    real = _fast_checks.lane_checks
    monkeypatch.setattr(_fast_checks, "lane_checks", lambda *a: calls.append(1) or real(*a))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = checks.lane_checks(b, prm, fleet)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = checks.lane_checks(b, prm, fleet)
    assert calls == [1]
    for name, a, r in zip(("collided", "violated", "min_ratio"), fast, reference, strict=True):
        same = (a == r) | (np.isnan(a) & np.isnan(r)) if a.dtype.kind == "f" else a == r
        assert same.all(), f"{name} differs at {np.flatnonzero(~same)[:5]}"
    collided, violated, ratio = reference
    assert 0 < collided.sum() < violated.sum() < bsz and np.isfinite(ratio).sum() > bsz // 2


def _random_motions(rng, n: int, knots: int, x0, v0, a_scale: float):
    """``n`` piecewise-constant-acceleration motions over ``[0, 0.1]`` with ``knots`` knots (some repeated: zero-length
    segments), integrated exactly."""
    from safelane.sim.kinematics import Motion

    inner = np.sort(rng.uniform(0.0, 0.1, (n, knots - 2)), axis=1)
    inner = np.where(rng.random(inner.shape) < 0.2, np.roll(inner, 1, axis=1), inner)  # repeated knots
    t = np.sort(np.column_stack([np.zeros(n), inner, np.full(n, 0.1)]), axis=1)
    acc = rng.uniform(-a_scale, a_scale, (n, knots - 1)) * (rng.random((n, knots - 1)) > 0.15)
    x, v = np.empty((n, knots)), np.empty((n, knots))
    x[:, 0], v[:, 0] = x0, v0
    for j in range(knots - 1):
        span = t[:, j + 1] - t[:, j]
        x[:, j + 1] = x[:, j] + v[:, j] * span + 0.5 * acc[:, j] * span * span
        v[:, j + 1] = v[:, j] + acc[:, j] * span
    return Motion(t=t, x=x, v=v, acc=acc)


@needs_numba
@pytest.mark.parametrize("lateral_knots", [2, 8])
def test_the_general_path_kernel_gives_windowed_gap_extremas_bits(lateral_knots):
    """The exact general path (an ego on its evasion plan, several segments) compiled: ``windowed_gap_extrema`` over
    ``crossing_knots`` of the lateral motion, on random multi-segment motions with zero-length segments, lateral
    motions crossing the level once, twice or not at all, and motions exactly at the level."""
    from safelane.sim import _fast_checks
    from safelane.sim.kinematics import crossing_knots, windowed_gap_extrema

    rng = np.random.default_rng(lateral_knots)
    n, level = 20_000, 0.85
    behind = _random_motions(rng, n, 8, rng.uniform(-5.0, 5.0, n), rng.uniform(0.0, 30.0, n), 6.0)
    ahead = _random_motions(rng, n, 3, rng.uniform(-12.0, 12.0, n), rng.uniform(0.0, 30.0, n), 6.0)
    y0 = np.where(rng.random(n) < 0.1, level, level + rng.uniform(-0.1, 0.1, n))
    lateral = _random_motions(rng, n, lateral_knots, y0, rng.uniform(-1.5, 1.5, n), 3.0)
    lo, hi = windowed_gap_extrema(behind, ahead, lateral, crossing_knots(lateral, level), level)
    got_lo, got_hi = _fast_checks._general(behind, ahead, lateral, level)
    for name, a, r in (("min", got_lo, lo), ("max", got_hi, hi)):
        same = (a == r) | (np.isnan(a) & np.isnan(r))
        assert same.all(), f"{name} differs at {np.flatnonzero(~same)[:5]}: {a[~same][:3]} vs {r[~same][:3]}"
    windowed = np.isfinite(lo)
    assert 0.2 < windowed.mean() < 0.99  # windows empty, partial and whole
