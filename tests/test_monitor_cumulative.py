"""The monitor's cumulative comparison (``shield/monitor.py``, :class:`~safelane.shield.monitor.Anchor`): with a
sensing-error box, a vehicle that stays inside the box each period but drifts beyond the held plan's worst case over
several periods is flagged; a vehicle within its assumptions under any measurement error inside the box is not.

The corners are the shield's: the anchor (and each period's snapshot) at the analysis' corner of the box — a leader
``box`` lower and slower than measured, F higher and faster — and the observation at the far corner (a leader
``box`` higher than measured). Motion is exact per period (constant deceleration, stopping at rest)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from safelane import Params
from safelane.shield.monitor import BREACH_KINDS, Anchor, Breach, Snapshot, observe_breaches

PRM = Params(a_x_d=6.0, a_o_d=9.5)  # the realistic split: others up to 9.5, the ego commits to 6
POS_BOX, SPEED_BOX = 1.0, 0.5  # a non-connected vehicle's sensing bounds (SensingBounds' defaults)


def _move(x, v, decel, dt):
    """Exact motion at constant deceleration ``decel`` (>= 0) for ``dt``, stopping at rest."""
    t = np.minimum(dt, np.where(decel > 0, v / np.where(decel > 0, decel, 1.0), np.inf))
    return x + v * t - 0.5 * decel * t * t, np.maximum(v - decel * t, 0.0)


def _run(decels, err_x, err_v, anchored: bool, f_accel=None, own=None):
    """Drive ``B`` scenarios of a non-connected L1 (``N = 0``) for ``len(decels)`` periods; ``decels (T, B)`` its true
    deceleration per period, ``err_x/err_v (T+1, B)`` the measurement errors; the held plan (made at ``t = 0``)
    assumed ``a_o_d``. Returns the monitor's record after each period."""
    steps, b = decels.shape
    dt = PRM.dt
    own = np.zeros((steps, b)) if own is None else own  # L0 cruises unless told
    x, v = np.full(b, 40.0), np.full(b, 35.0)
    fx, fv = np.full(b, -30.0), np.full(b, 20.0)
    ox, ov = np.full(b, 60.0), np.full(b, 30.0)

    def corners(k, x, v):
        meas_x, meas_v = x + err_x[k], v + err_v[k]
        return meas_x - POS_BOX, np.maximum(meas_v - SPEED_BOX, 0.0), meas_x + POS_BOX

    low_x, low_v, _ = corners(0, x, v)
    o_low, o_vlow, _ = corners(0, ox, ov)
    a_o = np.full(b, PRM.others_decel)
    anchor = Anchor(
        t=np.zeros(b), f_t=np.zeros(b), own_t=np.zeros(b),
        chain_x=low_x[:, None], chain_v=low_v[:, None], bounds=a_o[:, None], l1_decel=a_o,
        n_connected=np.zeros(b, np.int64), f_x=fx + POS_BOX, f_v=fv + SPEED_BOX,
        f_accel=np.full(b, np.inf) if f_accel is None else np.full(b, PRM.a_x_a), own_x=o_low, own_v=o_vlow,
        own_decel=a_o,
    ) if anchored else None  # fmt: skip
    breach, records = Breach.none(b), []
    for k in range(steps):
        last = Snapshot(
            chain_x=low_x[:, None], chain_v=low_v[:, None], bounds=a_o[:, None], n_connected=np.zeros(b, np.int64),
            f_x=fx + POS_BOX, f_v=fv + SPEED_BOX, f_limit=np.full(b, np.inf), plan_l1_decel=a_o,
            plan_f_aggr=np.full(b, f_accel is not None), active=np.ones(b, bool), anchor=anchor,
        )  # fmt: skip
        x, v = _move(x, v, decels[k], dt)
        fx, fv = (fx + fv * dt + 0.5 * f_accel[k] * dt * dt, fv + f_accel[k] * dt) if f_accel is not None else (fx, fv)
        ox, ov = _move(ox, ov, own[k], dt)
        low_x, low_v, high_x = corners(k + 1, x, v)
        own_high = corners(k + 1, ox, ov)[2]
        seen = SimpleNamespace(chain_x=high_x[:, None], f_x=fx - POS_BOX, own_x=own_high[:, None])
        breach = observe_breaches(breach, last, seen, PRM, (k + 1) * dt)
        records.append(breach)
    return records


@pytest.mark.parametrize("rows", [8, 96])  # NumPy, and the compiled kernel from FAST_MIN_ROWS (where numba runs)
def test_a_leader_braking_one_beyond_its_maximum_for_two_seconds_inside_the_box_is_flagged(rows):
    """L1 (not connected) brakes at a_o_d + 1 for 2 s, then at a_o_d; every measurement at the edge of the box that
    hides the most (measured 1 m ahead, 0.5 m/s faster). Each period's excess (5 mm) is far inside the 2 m the box
    allows, so the per-period check alone never flags it; from the held plan's anchor the deficit reaches the box
    (½·1·2² = 2 m) at 2 s and passes it at the next period, where the monitor flags ``l1_decel`` and ``last_decel``."""
    steps = 30
    decels = np.where(np.arange(steps)[:, None] < 20, PRM.others_decel + 1.0, PRM.others_decel) + np.zeros((1, rows))
    err_x, err_v = np.full((steps + 1, rows), POS_BOX), np.full((steps + 1, rows), SPEED_BOX)
    held = _run(decels, err_x, err_v, anchored=True)[-1]
    kinds = [BREACH_KINDS.index("l1_decel"), BREACH_KINDS.index("last_decel")]
    assert held.flags[:, kinds].all() and not held.flags[:, [1, 3, 4]].any()
    np.testing.assert_allclose(held.first_s, 2.1)
    per_period = _run(decels, err_x, err_v, anchored=False)[-1]
    assert not per_period.flags.any()


@pytest.mark.parametrize("rows", [8, 96])
def test_vehicles_within_their_assumptions_under_sensing_error_are_never_flagged(rows):
    """L1 braking at random decelerations up to a_o_d (some periods exactly at it), L0 likewise, an aggressive F
    accelerating up to a_x_a, measurement errors anywhere in the box (a third of them at its ends): 3 s, no flag."""
    rng = np.random.default_rng(5)
    steps = 30
    decels = np.where(rng.random((steps, rows)) < 0.3, PRM.others_decel, rng.uniform(0.0, PRM.others_decel,
                                                                                     (steps, rows)))  # fmt: skip
    own = rng.uniform(0.0, PRM.others_decel, (steps, rows))
    f_accel = rng.uniform(-PRM.a_x_d, PRM.a_x_a, (steps, rows))
    f_accel[rng.random((steps, rows)) < 0.3] = PRM.a_x_a
    edge = lambda shape, box: np.where(rng.random(shape) < 1 / 3, box * rng.choice([-1.0, 1.0], shape),  # noqa: E731
                                       rng.uniform(-box, box, shape))  # fmt: skip
    err_x, err_v = edge((steps + 1, rows), POS_BOX), edge((steps + 1, rows), SPEED_BOX)
    out = _run(decels, err_x, err_v, anchored=True, f_accel=f_accel, own=own)[-1]
    assert not out.flags.any() and np.isnan(out.first_s).all()


def test_an_own_lane_leader_beyond_the_others_maximum_is_flagged_as_last_decel():
    """L0 braking at a_o_d + 1.5 for 2 s (L1 inside its assumptions): the cumulative comparison flags ``last_decel``
    (a non-connected leader beyond a_o_d), which the per-period check does not watch at all."""
    rows, steps = 8, 25
    decels = np.full((steps, rows), 1.0)
    own = np.full((steps, rows), PRM.others_decel + 1.5)
    zeros = np.zeros((steps + 1, rows))
    out = _run(decels, zeros, zeros, anchored=True, own=own)[-1]
    assert out.flags[:, BREACH_KINDS.index("last_decel")].all() and not out.flags[:, 0].any()
