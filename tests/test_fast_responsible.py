"""The compiled responsible-following bound (:func:`safelane.safety._fast.responsible_kernel`, numba) against the
NumPy path it accelerates (:func:`safelane.safety.responsible.responsible_bound` with ``SAFELANE_NO_NUMBA=1``).

The NumPy path is the reference (itself held to the exact check and an independent time-sampled reference in
``test_sim_responsible.py``). The kernel must give the same bits — compared with NaN equal to NaN — on random
rows, simulator-like rows where every bound binds somewhere, a grid of corners (zero and negative-zero slack,
infinite slack, stopped vehicles, zero and vanishing decelerations, equal speeds, a follower's own bound below the
vehicle ahead's) and NaN inputs. Skipped where numba is missing (extra ``fast``; ``make install`` installs it).
"""

from __future__ import annotations

import importlib.util
import itertools

import numpy as np
import pytest

from safelane import Params
from safelane.safety.responsible import responsible_bound

PRM = Params()
pytestmark = [
    pytest.mark.compiled,
    pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba is not installed"),
]


def _numpy_bound(monkeypatch, slack, v_f, v_l, lead, brake):
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    try:
        with np.errstate(all="ignore"):
            return responsible_bound(slack, v_f, v_l, lead, PRM, brake=brake)
    finally:
        monkeypatch.delenv("SAFELANE_NO_NUMBA")


def _kernel_bound(slack, v_f, v_l, lead, brake):
    from safelane.safety import _fast

    return _fast.responsible(slack, v_f, v_l, lead, brake, PRM.dt)


def _rows(n: int, seed: int):
    rng = np.random.default_rng(seed)
    near = rng.random(n) < 0.5  # half close behind, as in the simulator; half anywhere
    slack = np.where(near, rng.uniform(-0.5, 12, n), rng.uniform(-2, 60, n))
    v_f = rng.uniform(0, 35, n)
    v_l = np.where(near, np.clip(v_f + rng.normal(0, 4, n), 0, None), rng.uniform(0, 35, n))
    lead = rng.uniform(0, PRM.a_x_d, n)
    brake = np.where(rng.random(n) < 0.5, PRM.a_x_d, rng.uniform(0.5, PRM.a_x_d, n))
    lead[::3], v_f[::11], v_l[::13] = PRM.a_x_d, 0.0, 0.0
    return slack, v_f, v_l, lead, brake


def _corners():
    slack = (-1.0, -0.0, 0.0, 1e-12, 0.35, 5.0, np.inf)
    speed = (0.0, 1e-9, 9.0, 9.25, 30.0)
    decel = (0.0, 1e-12, 3.0, PRM.a_x_d)
    brake = (0.5, 3.0, PRM.a_x_d)
    return [np.array(c, dtype=float) for c in zip(*itertools.product(slack, speed, speed, decel, brake), strict=True)]


@pytest.mark.parametrize("seed", range(3))
def test_kernel_gives_the_numpy_paths_bits_on_random_rows(monkeypatch, seed):
    rows = _rows(200_000, seed)
    expected = _numpy_bound(monkeypatch, *rows)
    got = _kernel_bound(*rows)
    assert got.shape == expected.shape and got.dtype == np.float64
    np.testing.assert_array_equal(got, expected)
    assert np.isfinite(expected).mean() > 0.5 and (expected == -np.inf).any()  # the rows reach every kind of answer


def test_kernel_gives_the_numpy_paths_bits_on_corners(monkeypatch):
    rows = _corners()
    np.testing.assert_array_equal(_kernel_bound(*rows), _numpy_bound(monkeypatch, *rows))


def test_kernel_propagates_nan_as_the_numpy_path(monkeypatch):
    rows = [np.array(col, dtype=float) for col in zip(*[
        (np.nan, 10.0, 10.0, 3.0, 8.0), (5.0, np.nan, 10.0, 3.0, 8.0), (5.0, 10.0, np.nan, 3.0, 8.0),
        (5.0, 10.0, 10.0, np.nan, 8.0), (5.0, 10.0, 10.0, 3.0, np.nan),
    ], strict=True)]  # fmt: skip
    expected = _numpy_bound(monkeypatch, *rows)
    np.testing.assert_array_equal(_kernel_bound(*rows), expected)  # NaN == NaN here
    assert np.isnan(expected).any()


def test_kernel_broadcasts_like_the_numpy_path(monkeypatch):
    slack = np.linspace(-1.0, 30.0, 12).reshape(3, 4)
    args = (slack, 20.0, np.array([15.0, 20.0, 25.0, 30.0]), 6.0, PRM.a_x_d)
    got = _kernel_bound(*args)
    assert got.shape == (3, 4)
    np.testing.assert_array_equal(got, _numpy_bound(monkeypatch, *args))


def test_responsible_bound_runs_the_kernel_from_its_batch_threshold(monkeypatch):
    from safelane.safety import _fast, responsible

    calls = []
    real = _fast.responsible
    monkeypatch.setattr(_fast, "responsible", lambda *a: calls.append(np.shape(a[0])) or real(*a))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    n = responsible.FAST_MIN_BATCH
    rows = _rows(n, 7)
    big = responsible_bound(*rows[:4], PRM, brake=rows[4])
    small = responsible_bound(*(r[: n - 1] for r in rows[:4]), PRM, brake=rows[4][: n - 1])
    assert calls == [(n,)]  # the kernel ran for the batch at the threshold, not for the one below it
    np.testing.assert_array_equal(big, _numpy_bound(monkeypatch, *rows))
    np.testing.assert_array_equal(small, big[: n - 1])
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    responsible_bound(*rows[:4], PRM)
    assert len(calls) == 1  # the switch keeps the NumPy path


def test_the_simulator_gives_the_same_table_with_and_without_the_kernel(monkeypatch):
    """The closed loop calls the bound for the completed ego and the monitor: with the kernel (batch above the
    threshold) the per-scenario table is the NumPy path's, column for column."""
    from safelane.safety import _fast
    from safelane.shield import fast_step
    from safelane.sim import SimConfig, concat, paper_scenarios, simulate_batch

    calls = []
    real = _fast.responsible
    monkeypatch.setattr(_fast, "responsible", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")  # the period-by-period path, which calls this kernel
    # ... through the shield's stages: the compiled period (shield/fast_step.py) calls the closed forms directly
    monkeypatch.setattr(fast_step, "kernel", lambda: None)

    planners = ("CV_all", "CV_none")
    batch = concat([paper_scenarios(p, 3, 5.0, 150, np.random.default_rng(k)) for k, p in enumerate(planners)])
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = simulate_batch(batch, seed=3, config=SimConfig()).table
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    reference = simulate_batch(batch, seed=3, config=SimConfig()).table
    # The leaders and F run their own fused kernels (sim/_fast_traffic); the shield calls this one for the completed
    # ego's responsible following and the monitor's watch on F.
    assert fast.equals(reference) and len(calls) > 10
    assert reference["n_abort"].sum() > 0 and reference["success"].any()


def test_a_column_of_broadcast_arrays_raises_no_futurewarning_and_the_callers_array_stays_writeable():
    # Seen in `safelane reproduce --workers 2`: numba's typing read the deprecated "writeable with a warning" flag of
    # a view of an np.broadcast_arrays output and NumPy emitted a FutureWarning on every such call.
    import warnings

    from safelane.safety import _fast

    wide, _ = np.broadcast_arrays(np.linspace(-1.0, 20.0, 300)[:, None], np.ones((1, 2)))
    column = wide[:, 0]
    mine = np.linspace(-1.0, 20.0, 300)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = _fast.responsible(column, 30.0, 29.0, 6.0, 6.0, 0.1)
        want = _fast.responsible(mine, 30.0, 29.0, 6.0, 6.0, 0.1)
    assert np.array_equal(got, want)
    mine[0] = 5.0  # still the caller's writeable array
    assert mine.flags.writeable
