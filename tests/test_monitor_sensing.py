"""The monitor's F check with a sensing box: a measurement error is never taken for a breach, a real one still is.

The false alarm this pins (found by the realistic-world falsifier: 6 of 191,467 scenarios on seed 22, all
``follower`` at the first comparison): F exactly at its margin behind a faster ego, measured at one edge of its box
and then at the other. At the analysis' corner (F high and fast) the gap is below the margin, and the responsible
limit there is full braking, which F, truly behind its margin and falling back, need not use. The limit is taken at
the corner that allows F the most; the prediction still starts from the analysis' corner.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from safelane import Params
from safelane.shield import ShieldConfig, Situation
from safelane.shield import core as shield

PRM = Params()
DT = PRM.dt


def _situation(t, ex, ev, fx, fv, err_f):
    b = len(ex)
    s = Situation.from_arrays(
        t=t, ego=(ex, np.zeros(b), ev, np.zeros(b)), follower=(fx, fv), leaders=(ex[:, None] + 150.0,
        np.full((b, 1), 30.0)), n_connected=0, f_connected=True, f_collaborative=True, params=PRM, geometry="ignore",
    )  # fmt: skip
    err = np.broadcast_to(np.asarray(err_f, float), (b, 2)).copy()
    return dataclasses.replace(s, err_f=err)


def _follower_flag(ex, ev, f_true, f_true_v, f_acc, err, meas0, meas1):
    """The ``follower`` flag after one period: F truly at ``(f_true, f_true_v)`` accelerating at ``f_acc`` (by hand,
    no stop inside the period), measured at ``true + meas0`` then ``true + meas1`` (position, speed offsets inside
    the box); the ego cruising."""
    cfg = ShieldConfig(sensing=True)
    s0 = _situation(0.0, ex, ev, f_true + meas0[0], f_true_v + meas0[1], err)
    state = shield.init(s0, PRM, cfg, "CV_all")
    state, d = shield.step(state, s0, (np.zeros(len(ex)), np.zeros(len(ex))), PRM, cfg, "CV_all")
    f1 = f_true + f_true_v * DT + 0.5 * f_acc * DT * DT
    v1 = f_true_v + f_acc * DT
    e1 = ex + ev * DT
    s1 = _situation(DT, e1, ev, f1 + meas1[0], v1 + meas1[1], err)
    state = shield.observe(state, s1, PRM)
    return state.breach.flags[:, 3], d


def test_an_f_at_its_margin_measured_at_both_edges_is_no_breach():
    """F at (and a hair behind) its margin, 2–6 m/s slower than the ego, braking gently: responsible by hand (it
    falls back from a gap at its margin and can brake at a_o_d >= the ego's a_x_d). Measured at the low edge of a
    1 m / 0.5 m/s box, then at the high edge: the prediction from the analysis' corner and the observation at the
    opposite corner straddle the truth by the box; only the limit could flag it, and it must not."""
    b = 12
    ex, ev = np.zeros(b), np.full(b, 41.0)
    f_x = ex - PRM.p_m - np.tile([0.0, 1e-8, 0.01], 4)
    f_v = ev - np.repeat([2.0, 3.0, 4.0, 6.0], 3)
    flag, d = _follower_flag(ex, ev, f_x, f_v, -1.0, (1.0, 0.5), (-0.99, -0.45), (0.99, 0.45))
    assert (d.behaviour != 2).all()  # a plan was accepted with F collaborative: F is watched
    assert not flag.any()


def test_an_f_pushing_into_the_ego_is_still_a_breach_with_a_small_box():
    """F 3 m/s faster than the ego, 2 m beyond its margin — a responsible F must brake — accelerating at a_x_a
    instead, measured at the worst edges of a 1 mm / 1 mm/s box: more than the box and the tolerance ahead of where
    any responsible F in the box could be."""
    b = 4
    ex, ev = np.zeros(b), np.full(b, 20.0)
    f_x, f_v = ex - PRM.p_m - 2.0, ev + 3.0
    flag, d = _follower_flag(ex, ev, f_x, f_v, PRM.a_x_a, (1e-3, 1e-3), (1e-3, 1e-3), (-1e-3, -1e-3))
    assert (d.behaviour != 2).all()
    assert flag.all()
    # The same F braking as a responsible follower must (at a_o_d) is no breach.
    flag_ok, _ = _follower_flag(ex, ev, f_x, f_v, -PRM.others_decel, (1e-3, 1e-3), (1e-3, 1e-3), (-1e-3, -1e-3))
    assert not flag_ok.any()
