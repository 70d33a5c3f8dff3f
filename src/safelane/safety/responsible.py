"""Responsible following: the largest acceleration that keeps a follower able to keep its margin (pure math).

A responsible follower picks the largest acceleration ``a <= a_wanted`` such that after one period at ``a`` it
can still keep its margin by braking at ``brake`` (default ``a_x_d``) while the vehicle ahead brakes at its worst
case (RSS's proper response with a one-period response time); if none exists it brakes at ``a_x_d``. Used by the
traffic behaviours (:mod:`safelane.sim.behaviours`) and by the shield (the ego after completion, the monitor).
"""

from __future__ import annotations

import math

import numpy as np

from .._motion import advance, stop_time
from ..params import Params
from ._backend import ARRAY
from .chain import min_follow_decel
from .evasion import fast_kernel


def pair_min_gap(slack, v_f, a_f, v_l, a_l, dt):
    """Exact minimum over ``[0, dt]`` of ``x_l − x_f − margin`` for two constant-acceleration motions with
    stopping, given the initial ``slack = x_l − x_f − margin``."""
    ts_f, ts_l = stop_time(v_f, a_f, dt), stop_time(v_l, a_l, dt)
    dv, da = v_l - v_f, a_f - a_l
    tau = np.where(da != 0.0, dv / np.where(da != 0.0, da, 1.0), 0.0)
    # All candidate instants at once (stops, equal speeds, end of period): one stacked evaluation.
    t = np.stack(np.broadcast_arrays(ts_f, ts_l, np.clip(tau, 0.0, dt), np.full_like(ts_f, dt)))
    # Positions at those instants, stopping at rest: each vehicle moves until min(t, its stop time).
    m_f, m_l = np.minimum(t, ts_f), np.minimum(t, ts_l)
    xf = v_f * m_f + 0.5 * a_f * m_f * m_f
    xl = slack + v_l * m_l + 0.5 * a_l * m_l * m_l
    return np.minimum(slack, (xl - xf).min(0))


def responsible_ok(a, slack, v_f, v_l, lead_decel, prm: Params, brake=None, tol: float = 0.0):
    """True where accelerating at ``a`` for one period still lets the follower keep its margin by braking at
    ``brake`` (default ``a_x_d``) afterwards, with the vehicle ahead braking at ``lead_decel`` from now on: the
    definition that :func:`responsible_accel` solves in closed form (exact gap minimum over the period, then
    Eqs. 2–3). ``tol``: gaps this far inside the margin still count as kept (round-off)."""
    a, slack, v_f, v_l, lead_decel = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (a, slack, v_f, v_l, lead_decel))
    )
    dt = prm.dt
    in_period = pair_min_gap(slack, v_f, a, v_l, -lead_decel, dt) >= -tol
    xf, vf = advance(0.0, v_f, a, dt)
    xl, vl = advance(slack, v_l, -lead_decel, dt)
    with np.errstate(all="ignore"):
        z = min_follow_decel(ARRAY, xl - xf, vf, vl, lead_decel)
    return in_period & (z <= (prm.a_x_d if brake is None else brake))


def final_stop_accel(slack, v_f, v_l, lead_decel, prm: Params, brake=None):
    """Largest ``a`` for which the follower's final stopping point (``a`` for one period, then ``a_x_d``) stays
    behind the leader's (braking at ``lead_decel``): a necessary condition of :func:`responsible_ok`, in
    closed form. ``+inf`` where the leader never stops; ``-inf`` where even stopping at once is too late.

    With ``w = v_f + a·dt >= 0`` the follower stops at ``(v_f + w)·dt/2 + w²/(2 a_x_d)``; setting that equal to the
    leader's stop ``Y = slack + v_l²/(2 lead_decel)`` gives ``w = −B dt/2 + sqrt(B² dt²/4 + B (2Y − v_f dt))``.
    When that ``w`` is negative the follower stops inside the period, at ``v_f²/(2|a|)``, so ``a = −v_f²/(2Y)``.
    """
    dt = prm.dt
    brake = prm.a_x_d if brake is None else brake
    with np.errstate(all="ignore"):
        lead_stop = np.where(
            lead_decel > 0.0,
            v_l * v_l / (2.0 * np.where(lead_decel > 0.0, lead_decel, 1.0)),
            np.where(v_l > 0.0, np.inf, 0.0),
        )
        y = slack + lead_stop
        w = -0.5 * brake * dt + np.sqrt(np.maximum(0.25 * brake * brake * dt * dt + brake * (2.0 * y - v_f * dt), 0.0))
        a_moving = (w - v_f) / dt
        a_stopping = np.where(y > 0.0, -v_f * v_f / (2.0 * np.where(y > 0.0, y, 1.0)), -np.inf)
        a = np.where(w >= 0.0, a_moving, a_stopping)
    # Both stops at the same point with the follower already at rest: staying (a = 0) is the bound.
    at_rest_there = (y == 0.0) & (v_f == 0.0)
    return np.where(np.isinf(y) & (y > 0), np.inf, np.where(y <= 0.0, np.where(at_rest_there, 0.0, -np.inf), a))


ROOT_EPS_MPS2 = 1e-9  # m/s²: the closed-form bound is applied this far on the safe side (rounding at the boundary)
#: Elements from which :func:`responsible_bound` runs the compiled kernel (its call costs a few µs; the NumPy path
#: ~50 array operations).
FAST_MIN_BATCH = 256


def responsible_bounds(slack, v_f, v_l, lead_decel, prm: Params, brake=None) -> dict[str, np.ndarray]:
    """The closed-form upper bounds whose minimum is :func:`responsible_accel`'s answer, by the way the margin
    binds (``+inf`` where a case does not hold at its root). The follower is at ``a`` for one period, then brakes
    at ``B = a_x_d``; the leader brakes at ``d = lead_decel`` throughout; ``x_l(dt)``, ``u1``: the leader's
    gap position and speed at ``dt``. Each root is kept only where its case holds at the root; it is then an
    upper bound on the safe ``a``, and the binding one is the answer.

    * ``inside`` — already inside the margin (``slack < 0``): nothing is safe, ``−inf``;
    * ``final`` — the follower stops where the leader stops (:func:`final_stop_accel`); always a bound;
    * ``end`` — the gap is zero at ``dt``: ``a = 2 (x_l(dt) − v_f dt) / dt²`` (or ``−v_f² / (2 x_l(dt))`` when the
      follower would stop inside the period); always a bound, though it binds alone only in ties (a gap
      decreasing at ``dt`` keeps decreasing after it, so a later bound is smaller), e.g. from zero slack;
    * ``in_period`` — equal speeds while both move (follower braking harder than the leader):
      ``a = −d − (v_f − v_l)² / (2 slack)``, where the equal-speed instant ``2 slack / (v_f − v_l)`` lies inside
      the period before the leader stops;
    * ``after_period`` — equal speeds while both move (``B > d``): with ``q = v_f + a dt − u1``,
      ``G = x_l(dt) − v_f dt`` and ``c = B − d``, the gap at that instant ``G − a dt²/2 − q²/(2c)`` is zero at
      ``q = (−c dt + sqrt(c² dt² + 4c (2G + dt (v_f − u1)))) / 2``, where ``q > 0`` and the instant ``q / c``
      after the period comes before the leader stops.
    """
    dt = prm.dt
    brake = prm.a_x_d if brake is None else brake
    slack = slack + 0.0  # −0.0 → +0.0: the in-period vertex divides by it, and −0.0 would flip its infinity's sign
    with np.errstate(all="ignore"):
        xl_end, u1 = advance(slack, v_l, -lead_decel, dt)
        g = xl_end - v_f * dt
        end = 2.0 * g / (dt * dt)
        end = np.where(v_f + end * dt >= 0.0, end, -v_f * v_f / (2.0 * xl_end))
        dv = v_f - v_l
        tau = 2.0 * slack / dv
        vertex = -lead_decel - dv * dv / (2.0 * slack)
        in_period = (dv > 0.0) & (slack >= 0.0) & (tau < dt) & (v_l - lead_decel * tau > 0.0)
        c = brake - lead_decel
        r0 = v_f - u1
        disc = c * c * dt * dt + 4.0 * c * (2.0 * g + dt * r0)
        q = 0.5 * (-c * dt + np.sqrt(disc))
        after = (q - r0) / dt
        after_period = (c > 0.0) & (disc >= 0.0) & (q > 0.0) & (u1 > 0.0) & (q * lead_decel <= c * u1)
        return {
            "inside": np.where(slack >= 0.0, np.inf, -np.inf),
            "final": final_stop_accel(slack, v_f, v_l, lead_decel, prm, brake),
            "end": np.where(xl_end > 0.0, end, np.where(xl_end < 0.0, -np.inf, 0.0)),
            "in_period": np.where(in_period, vertex, np.inf),
            "after_period": np.where(after_period, after, np.inf),
        }


def responsible_bound(slack, v_f, v_l, lead_decel, prm: Params, brake=None):
    """The smallest of :func:`responsible_bounds`: the largest safe acceleration, in closed form (exact for
    ``brake >= lead_decel``, always the case with the default ``a_x_d``; a softer ``brake`` admits one more case,
    the follower stopping first, that the caller must check — see :func:`leader_accels`).

    NumPy batches of :data:`FAST_MIN_BATCH` elements or more run the compiled kernel
    (:func:`._fast.responsible_kernel`, extra ``fast``) where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``:
    the same bits as the NumPy path below, which stays the reference (``tests/test_fast_responsible.py``)."""
    shape = np.broadcast_shapes(*(np.shape(x) for x in (slack, v_f, v_l, lead_decel)))
    if math.prod(shape) >= FAST_MIN_BATCH and (kernel := fast_kernel()) is not None:
        return kernel.responsible(slack, v_f, v_l, lead_decel, prm.a_x_d if brake is None else brake, prm.dt)
    bounds = iter(responsible_bounds(slack, v_f, v_l, lead_decel, prm, brake).values())
    out = next(bounds)
    for b in bounds:
        out = np.minimum(out, b)
    return out


def responsible_accel(a_wanted, slack, v_f, v_l, lead_decel, prm: Params):
    """Largest ``a`` in ``[−a_x_d, a_wanted]`` passing :func:`responsible_ok`; ``−a_x_d`` when none does.

    The safe ``a`` form an interval ``[−a_x_d, a*]`` (a larger ``a`` puts the follower further ahead at every
    instant), and ``a*`` is :func:`responsible_bound`, applied ``1e-9`` m/s² on the safe side (rounding at the
    boundary). Closed form throughout; the tests hold it to the full check, safe and maximal to ``1e-7``, on random
    and adversarial (Hypothesis) rows, and to an independent time-sampled reference.
    """
    a_wanted, slack, v_f, v_l, lead_decel = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (a_wanted, slack, v_f, v_l, lead_decel))
    )
    bound = responsible_bound(slack, v_f, v_l, lead_decel, prm)
    return np.where(bound > a_wanted, a_wanted, np.maximum(bound - ROOT_EPS_MPS2, -prm.a_x_d))
