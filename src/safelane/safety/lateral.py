"""Fastest lateral return to the original lane (paper Eq. 5).

The ego's centre is at ``p_y`` (original lane centre ``y = 0``, target lane centre ``y = w_l``). It lies
wholly in its original lane when ``p_y <= y_s = (w_l − w_v)/2``. Write ``e = p_y − y_s`` for the intrusion
and ``s = e + v_y|v_y|/(2 a_y_m)`` for where the ego would come to rest laterally if it braked its lateral
speed at once. Cases (``a = a_y_m``):

* **nothing to evade** — ``e <= 0`` and (``v_y <= 0`` or ``s <= 0``): the ego never leaves its lane;
  ``t_y_f = 0``.
* **bang-bang** (``s > 0``; the paper's case) — ``−a`` on ``[0, t_1]``, then ``+a`` until ``y = y_s`` with
  ``v_y = 0``. Solving Eq. 5: ``t_1 = (v_y + r)/a``, ``t_y_f = (v_y + 2r)/a`` with ``r = sqrt(a e + v_y²/2)``.
* **already returning fast** (``e > 0``, ``v_y < 0``, ``s <= 0``; missing in the paper) — the ego cannot
  stop at ``y_s`` and will cross it whatever it does; the plan brakes the lateral speed (``+a``) and the
  intrusion ends at the first root of ``e + v_y t + a t²/2 = 0``: ``t_y_f = (−v_y − sqrt(v_y² − 2 a e))/a``,
  ``t_1 = 0``.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..tolerances import DIST_TOL_M
from ._backend import jitable
from ._checks import check_params, finish, prepare

#: Intrusions up to this many metres beyond ``y_s`` count as none (round-off of the exact return profile).
LATERAL_TOL_M = DIST_TOL_M


def lateral_core(xp, p_y, v_y, params: Params):
    """Backend-generic core: returns ``(t_y_f, t_1, acc_1, acc_2, t_end)``.

    The lateral evasion profile is ``acc_1`` on ``[0, t_1]``, ``acc_2`` on ``[t_1, t_end]`` and zero lateral
    acceleration afterwards (lateral speed is then zero).
    """
    a = params.a_y_m
    e = p_y - params.y_safe
    s = e + v_y * abs(v_y) / (2.0 * a)
    # Within LATERAL_TOL_M of the line counts as back: the return profile lands on y_s up to round-off.
    nothing = (e <= LATERAL_TOL_M) & ((v_y <= 0.0) | (s <= LATERAL_TOL_M))
    above = s > 0.0  # disjoint from `nothing`
    r = xp.sqrt(a * e + 0.5 * v_y * v_y)
    t_bb = (v_y + 2.0 * r) / a
    t_back = (-v_y - xp.sqrt(v_y * v_y - 2.0 * a * e)) / a
    t_y_f = xp.where(nothing, 0.0, xp.where(above, t_bb, t_back))
    t_1 = xp.where(above, (v_y + r) / a, 0.0)
    acc_1 = xp.where(above, -a, 0.0)
    acc_2 = xp.where(nothing, xp.where(v_y > 0.0, -a, a), a)
    t_end = xp.where(above, t_bb, abs(v_y) / a)
    return t_y_f, t_1, acc_1, acc_2, t_end


def lateral_state(xp, t, p_y, v_y, t_1, acc_1, acc_2, t_end):
    """Lateral position and speed of the evasion profile at time ``t`` (backend-generic, exact)."""
    ta = xp.minimum(t, t_1)
    y = p_y + v_y * ta + 0.5 * acc_1 * ta * ta
    vy = v_y + acc_1 * ta
    tb = xp.maximum(xp.minimum(t, t_end) - t_1, 0.0)
    y = y + vy * tb + 0.5 * acc_2 * tb * tb
    vy = vy + acc_2 * tb
    return y, vy


def lateral_evasion_time(p_y, v_y, params: Params):
    """Time ``t_y_f`` of the fastest return to ``p_y = (w_l − w_v)/2`` with zero lateral speed (Eq. 5).

    Args:
        p_y: lateral centre position [m], any shape.
        v_y: lateral speed [m/s] (positive toward the target lane), broadcastable with ``p_y``.

    Returns:
        ``(t_y_f, t_switch)``: float64 arrays of the broadcast shape. ``t_y_f = 0`` when there is nothing to
        evade; ``t_switch`` is when the lateral acceleration flips from ``−a_y_m`` to ``+a_y_m``.
    """
    check_params(params)
    xp, a, shape = prepare({"p_y": p_y, "v_y": v_y})
    with np.errstate(all="ignore"):
        t_y_f, t_1, *_ = lateral_core(xp, a["p_y"], a["v_y"], params)
    return finish(xp, shape, t_y_f), finish(xp, shape, t_1)


# The closed forms compiled into the kernels (safety/_compile.py): the same functions, evaluated row by row.
jitable(lateral_core, lateral_state)
