"""Responsible following: the largest acceleration that keeps a follower able to keep its margin (pure math).

A responsible follower picks the largest acceleration ``a <= a_wanted`` such that after one period at ``a`` it
can still keep its margin by braking at ``brake`` (default ``a_x_d``) while the vehicle ahead brakes at its worst
case (RSS's proper response with a one-period response time); if none exists it brakes at ``a_x_d``. Used by the
traffic behaviours (:mod:`safelane.sim.behaviours`) and by the shield (the ego after completion, the monitor).

**One source.** Each rule is one backend-generic function (``*_core``, first argument the backend ``xp`` of
:mod:`._backend`, marked ``jitable`` at the end of the module): the public functions below run it on NumPy arrays
(validation-free wrappers with ``errstate`` and, for :func:`responsible_bounds`, named output), and the compiled
rows (:mod:`._fast_responsible`, and through it the simulator's and the shield's kernels) run the very same
function on floats. The exact one-period motion is :func:`safelane._motion.advance_core`, the chain link's
deceleration :func:`.chain.min_follow_decel`, both marked too.
"""

from __future__ import annotations

import math

import numpy as np

from .._motion import advance_core, stop_time_core
from ..params import Params
from ..tolerances import ACCEL_TOL_MPS2
from ._backend import ARRAY, FEASIBILITY_TOL_M, INF, jitable
from .chain import min_follow_decel
from .evasion import fast_kernel


def pair_min_gap_core(xp, slack, v_f, a_f, v_l, a_l, dt):
    """Backend-generic :func:`pair_min_gap`: the gap at each candidate instant (both stops, the equal-speed instant
    clipped into the period, the period's end), the smallest of them and ``slack`` (NaN propagates)."""
    ts_f, ts_l = stop_time_core(xp, v_f, a_f, dt), stop_time_core(xp, v_l, a_l, dt)
    tau = xp.div(v_l - v_f, a_f - a_l, 0.0)
    lowest = _gap_at(xp, ts_f, slack, v_f, a_f, ts_f, v_l, a_l, ts_l)
    lowest = xp.minimum(lowest, _gap_at(xp, ts_l, slack, v_f, a_f, ts_f, v_l, a_l, ts_l))
    lowest = xp.minimum(lowest, _gap_at(xp, xp.clip(tau, 0.0, dt), slack, v_f, a_f, ts_f, v_l, a_l, ts_l))
    lowest = xp.minimum(lowest, _gap_at(xp, dt, slack, v_f, a_f, ts_f, v_l, a_l, ts_l))
    return xp.minimum(slack, lowest)


def _gap_at(xp, t, slack, v_f, a_f, ts_f, v_l, a_l, ts_l):
    """``x_l − x_f − margin`` at ``t``, each vehicle moving until ``min(t, its stop time)``."""
    m_f, m_l = xp.minimum(t, ts_f), xp.minimum(t, ts_l)
    xf = v_f * m_f + 0.5 * a_f * m_f * m_f
    xl = slack + v_l * m_l + 0.5 * a_l * m_l * m_l
    return xl - xf


def pair_min_gap(slack, v_f, a_f, v_l, a_l, dt):
    """Exact minimum over ``[0, dt]`` of ``x_l − x_f − margin`` for two constant-acceleration motions with
    stopping, given the initial ``slack = x_l − x_f − margin`` (NumPy; :func:`pair_min_gap_core`)."""
    return pair_min_gap_core(ARRAY, slack, v_f, a_f, v_l, a_l, dt)


def responsible_ok_core(xp, a, slack, v_f, v_l, lead_decel, brake, dt, tol, link_tol=FEASIBILITY_TOL_M):
    """Backend-generic :func:`responsible_ok` (``brake`` and ``tol`` given); the deceleration needed after the
    period is :func:`.chain.min_follow_decel` at its tolerance ``link_tol``."""
    in_period = pair_min_gap_core(xp, slack, v_f, a, v_l, -lead_decel, dt) >= -tol
    xf, vf = advance_core(xp, 0.0, v_f, a, dt)
    xl, vl = advance_core(xp, slack, v_l, -lead_decel, dt)
    z = min_follow_decel(xp, xl - xf, vf, vl, lead_decel, link_tol)
    return in_period & (z <= brake)


def responsible_ok(a, slack, v_f, v_l, lead_decel, prm: Params, brake=None, tol: float = 0.0):
    """True where accelerating at ``a`` for one period still lets the follower keep its margin by braking at
    ``brake`` (default ``a_x_d``) afterwards, with the vehicle ahead braking at ``lead_decel`` from now on: the
    definition that :func:`responsible_accel` solves in closed form (exact gap minimum over the period, then
    Eqs. 2–3). ``tol``: gaps this far inside the margin still count as kept (round-off)."""
    a, slack, v_f, v_l, lead_decel = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (a, slack, v_f, v_l, lead_decel))
    )
    with np.errstate(all="ignore"):
        return responsible_ok_core(ARRAY, a, slack, v_f, v_l, lead_decel, prm.a_x_d if brake is None else brake,
                                   prm.dt, tol)  # fmt: skip


def final_stop_accel_core(xp, slack, v_f, v_l, lead_decel, brake, dt):
    """Backend-generic :func:`final_stop_accel` (``brake`` given)."""
    y = slack + xp.stop_dist(v_l, lead_decel)
    w = -0.5 * brake * dt + xp.sqrt(0.25 * brake * brake * dt * dt + brake * (2.0 * y - v_f * dt))
    a_moving = (w - v_f) / dt
    a_stopping = xp.where(y > 0.0, xp.div(-v_f * v_f, 2.0 * y, -INF), -INF)
    a = xp.where(w >= 0.0, a_moving, a_stopping)
    # Both stops at the same point with the follower already at rest: staying (a = 0) is the bound.
    at_rest_there = (y == 0.0) & (v_f == 0.0)
    return xp.where(y == INF, INF, xp.where(y <= 0.0, xp.where(at_rest_there, 0.0, -INF), a))


def final_stop_accel(slack, v_f, v_l, lead_decel, prm: Params, brake=None):
    """Largest ``a`` for which the follower's final stopping point (``a`` for one period, then ``a_x_d``) stays
    behind the leader's (braking at ``lead_decel``): a necessary condition of :func:`responsible_ok`, in
    closed form. ``+inf`` where the leader never stops; ``-inf`` where even stopping at once is too late.

    With ``w = v_f + a·dt >= 0`` the follower stops at ``(v_f + w)·dt/2 + w²/(2 a_x_d)``; setting that equal to the
    leader's stop ``Y = slack + v_l²/(2 lead_decel)`` gives ``w = −B dt/2 + sqrt(B² dt²/4 + B (2Y − v_f dt))``.
    When that ``w`` is negative the follower stops inside the period, at ``v_f²/(2|a|)``, so ``a = −v_f²/(2Y)``.
    """
    with np.errstate(all="ignore"):
        return final_stop_accel_core(ARRAY, slack, v_f, v_l, lead_decel, prm.a_x_d if brake is None else brake,
                                     prm.dt)  # fmt: skip


#: m/s²: the closed-form bound is applied this far on the safe side (rounding at the boundary).
ROOT_EPS_MPS2 = ACCEL_TOL_MPS2
#: Elements from which :func:`responsible_bound` runs the compiled kernel (its call costs a few µs; the NumPy path
#: ~50 array operations).
FAST_MIN_BATCH = 256


#: The cases of :func:`responsible_bounds`, in the order :func:`responsible_bounds_core` returns them.
BOUND_CASES = ("inside", "final", "end", "in_period", "after_period")


def responsible_bounds_core(xp, slack, v_f, v_l, lead_decel, brake, dt):
    """Backend-generic :func:`responsible_bounds` (``brake`` given): the five bounds as a tuple in the order of
    :data:`BOUND_CASES`. Every quotient that is used has a divisor that cannot be zero there (``dt``; ``2 x_l(dt)``
    where ``x_l(dt) > 0``; ``v_f − v_l`` where it is ``> 0``); ``2 slack`` is zero at zero slack, where a closing
    follower's in-period vertex is ``−inf`` (``xp.div``'s default)."""
    slack = slack + 0.0  # −0.0 → +0.0: the in-period vertex divides by it, and −0.0 would flip its infinity's sign
    xl_end, u1 = advance_core(xp, slack, v_l, -lead_decel, dt)
    g = xl_end - v_f * dt
    end = 2.0 * g / (dt * dt)
    end = xp.where(v_f + end * dt >= 0.0, end, xp.div(-v_f * v_f, 2.0 * xl_end, -INF))
    dv = v_f - v_l
    tau = xp.div(2.0 * slack, dv, INF)
    vertex = -lead_decel - xp.div(dv * dv, 2.0 * slack, INF)
    in_period = (dv > 0.0) & (slack >= 0.0) & (tau < dt) & (v_l - lead_decel * tau > 0.0)
    c = brake - lead_decel
    r0 = v_f - u1
    disc = c * c * dt * dt + 4.0 * c * (2.0 * g + dt * r0)
    q = 0.5 * (-c * dt + xp.sqrt(disc))  # disc < 0 (clamped here) is no case: after_period needs disc >= 0
    after = (q - r0) / dt
    after_period = (c > 0.0) & (disc >= 0.0) & (q > 0.0) & (u1 > 0.0) & (q * lead_decel <= c * u1)
    return (
        xp.where(slack >= 0.0, INF, -INF),
        final_stop_accel_core(xp, slack, v_f, v_l, lead_decel, brake, dt),
        xp.where(xl_end > 0.0, end, xp.where(xl_end < 0.0, -INF, 0.0)),
        xp.where(in_period, vertex, INF),
        xp.where(after_period, after, INF),
    )


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

    NumPy; the formulas are :func:`responsible_bounds_core`'s.
    """
    with np.errstate(all="ignore"):
        bounds = responsible_bounds_core(ARRAY, slack, v_f, v_l, lead_decel, prm.a_x_d if brake is None else brake,
                                         prm.dt)  # fmt: skip
    return dict(zip(BOUND_CASES, bounds, strict=True))


def responsible_bound_core(xp, slack, v_f, v_l, lead_decel, brake, dt):
    """Backend-generic :func:`responsible_bound`: the smallest of :func:`responsible_bounds_core`, taken in the
    order of :data:`BOUND_CASES` (NaN propagates)."""
    inside, final, end, in_period, after_period = responsible_bounds_core(xp, slack, v_f, v_l, lead_decel, brake, dt)
    return xp.minimum(xp.minimum(xp.minimum(xp.minimum(inside, final), end), in_period), after_period)


def responsible_bound(slack, v_f, v_l, lead_decel, prm: Params, brake=None):
    """The smallest of :func:`responsible_bounds`: the largest safe acceleration, in closed form (exact for
    ``brake >= lead_decel``, always the case with the default ``a_x_d``; a softer ``brake`` admits one more case,
    the follower stopping first, that the caller must check — see :func:`leader_accels`).

    NumPy batches of :data:`FAST_MIN_BATCH` elements or more run the compiled kernel
    (:func:`._fast.responsible_kernel`, extra ``fast``) where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``:
    :func:`responsible_bound_core` compiled, the same bits as on NumPy below (``tests/test_fast_responsible.py``)."""
    brake = prm.a_x_d if brake is None else brake
    shape = np.broadcast_shapes(*(np.shape(x) for x in (slack, v_f, v_l, lead_decel)))
    if math.prod(shape) >= FAST_MIN_BATCH and (kernel := fast_kernel()) is not None:
        return kernel.responsible(slack, v_f, v_l, lead_decel, brake, prm.dt)
    with np.errstate(all="ignore"):
        return responsible_bound_core(ARRAY, slack, v_f, v_l, lead_decel, brake, prm.dt)


def responsible_accel_core(xp, a_wanted, bound, a_x_d):
    """Backend-generic :func:`responsible_accel` from the bound (:func:`responsible_bound_core`)."""
    return xp.where(bound > a_wanted, a_wanted, xp.maximum(bound - ROOT_EPS_MPS2, -a_x_d))


def responsible_accel(a_wanted, slack, v_f, v_l, lead_decel, prm: Params, brake=None):
    """Largest ``a`` in ``[−B, a_wanted]`` passing :func:`responsible_ok`; ``−B`` when none does. ``B = brake``: the
    follower's own braking (default ``a_x_d``; another vehicle following brakes up to the others' maximum ``a_o_d``).

    The safe ``a`` form an interval ``[−B, a*]`` (a larger ``a`` puts the follower further ahead at every
    instant), and ``a*`` is :func:`responsible_bound`, applied ``1e-9`` m/s² on the safe side (rounding at the
    boundary). Closed form throughout; the tests hold it to the full check, safe and maximal to ``1e-7``, on random
    and adversarial (Hypothesis) rows, and to an independent time-sampled reference.
    """
    a_wanted, slack, v_f, v_l, lead_decel = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (a_wanted, slack, v_f, v_l, lead_decel))
    )
    brake = prm.a_x_d if brake is None else brake
    bound = responsible_bound(slack, v_f, v_l, lead_decel, prm, brake=brake)
    return responsible_accel_core(ARRAY, a_wanted, bound, brake)


# The closed forms compiled into the kernels (safety/_compile.py, through _fast_responsible): the same functions,
# evaluated row by row; with them the exact one-period motion of _motion, which imports nothing from safety.
jitable(
    stop_time_core, advance_core, _gap_at, pair_min_gap_core, responsible_ok_core, final_stop_accel_core,
    responsible_bounds_core, responsible_bound_core, responsible_accel_core,
)  # fmt: skip
