"""Optional compiled kernel of the shield's candidate check (:func:`~.decide.check_candidate`; numba, extra ``fast``).

:func:`candidate_kernel` is ``check_candidate`` for rows without an own-lane leader, element by element: the
period at the candidate's accelerations with L1 and F at their worst case (``_motion.advance``), the conflict-zone
test (``free_max``), both worst-case gaps over the period (``pair_min_gap``), whether the step completes, and the
evasion check with its whole plan from the predicted state (:func:`safelane.safety._fast._plan_parts`). The
completion rule itself runs afterwards on the completing rows (few), in NumPy, as in ``check_candidate``: any
registered rule works. Every expression is in the NumPy path's evaluation order (the shared scalar helpers), so
the verdicts and plans are its bits (``tests/test_fast_decide.py``); the NumPy function stays the reference and
the fallback (own-lane rows, ``SAFELANE_NO_NUMBA=1``, numba missing, small batches).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types

from ..params import Params
from ..safety._backend import ARRAY, FEASIBILITY_TOL_M
from ..safety._fast import BOOL_PARTS, FLOAT_PARTS, _plan_parts
from ..safety._fast_base import (
    _B,
    _F,
    _max,
    announce_compile,
    row_function,
)
from ..safety._fast_responsible import _advance, _pair_min_gap
from ..safety.lateral import LATERAL_TOL_M
from ..safety.plan import plan_from_core
from .decide import Verdict

announce_compile(__file__)

#: The rows of :func:`candidate_kernel`'s ``floats``: the predicted states, then the plan's float parts.
STATES = ("ex", "ey", "evx", "evy", "lx", "lv", "fx", "fv")
_SIGNATURE = types.void(
    *(_F,) * 11, _B, *(types.float64,) * 9, types.Array(types.float64, 2, "C"), types.Array(types.bool_, 2, "C")
)


@row_function
def _candidate(x, y, vx, vy, ax, ay, x1, v1, d1, xf, vf, aggr, a_a, a_d, a_ym, y_safe, p_m, dt, level, lat_tol, tol):
    """One row of :func:`candidate_kernel`: ``(state, period_ok, completing, parts, bits)`` — the predicted states
    (:data:`STATES`), the period's verdict, whether the step completes, and the plan from the predicted state
    (``_fast.FLOAT_PARTS``, ``_fast.BOOL_PARTS``)."""
    ex, evx = _advance(x, vx, ax, dt)
    ey = y + vy * dt + 0.5 * ay * dt * dt
    evy = vy + ay * dt
    lx, lv = _advance(x1, v1, -d1, dt)
    a_f = a_a if aggr else -a_d
    fx, fv = _advance(xf, vf, a_f, dt)
    # free_max(ego_y, ego_vy, a_y, dt): the largest lateral position over the period
    tau = -vy / ay if ay < 0.0 else -1.0
    vertex = y + 0.5 * vy * tau if (tau > 0.0 and tau < dt) else -np.inf
    conflict = _max(_max(y, ey), vertex) > y_safe + lat_tol
    gap_l = _pair_min_gap(x1 - x - p_m, vx, ax, v1, -d1, dt)
    gap_f = _pair_min_gap(x - xf - p_m, vf, a_f, vx, ax, dt)
    period_ok = (not conflict) or (gap_l >= -tol and gap_f >= -tol)
    parts, bits = _plan_parts(ey, evy, ex, evx, lx, lv, d1, fx, fv, aggr, p_m, p_m, a_a, a_d, a_ym, y_safe, tol)
    return (ex, ey, evx, evy, lx, lv, fx, fv), period_ok, ey >= level, parts, bits


@numba.njit(_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def candidate_kernel(
    ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggr, a_a, a_d, a_ym, y_safe, p_m, dt,
    level, lat_tol, tol, floats, flags,
):  # fmt: skip
    """Per row: ``floats`` ``(18, n)`` — :data:`STATES`, then ``_fast.FLOAT_PARTS``; ``flags`` ``(7, n)`` —
    ``period_ok``, ``completing``, then ``_fast.BOOL_PARTS``."""
    for i in range(floats.shape[1]):
        state, period_ok, completing, parts, bits = _candidate(
            ego_x[i], ego_y[i], ego_vx[i], ego_vy[i], a_x[i], a_y[i], l1_x[i], l1_v[i], l1_decel[i], f_x[i], f_v[i],
            f_aggr[i], a_a, a_d, a_ym, y_safe, p_m, dt, level, lat_tol, tol,
        )  # fmt: skip
        flags[0, i] = period_ok
        flags[1, i] = completing
        for j in range(8):
            floats[j, i] = state[j]
        for j in range(10):
            floats[8 + j, i] = parts[j]
        for j in range(5):
            flags[2 + j, i] = bits[j]


def check_candidate(ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive,
                    prm: Params, completion) -> Verdict:  # fmt: skip
    """:func:`~.decide.check_candidate` without an own-lane leader, through :func:`candidate_kernel`."""
    args = [np.asarray(a, dtype=np.float64) for a in (ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel,
                                                      f_x, f_v)]  # fmt: skip
    n = max(a.size for a in args)
    args = [np.broadcast_to(a, (n,)) for a in args] + [np.broadcast_to(np.asarray(f_aggressive, np.bool_), (n,))]
    level = completion.level(prm) if hasattr(completion, "level") else prm.y_boundary
    floats = np.empty((len(STATES) + len(FLOAT_PARTS), n))
    flags = np.empty((2 + len(BOOL_PARTS), n), dtype=np.bool_)
    candidate_kernel(*args, prm.a_x_a, prm.a_x_d, prm.a_y_m, prm.y_safe, prm.p_m, prm.dt, level, LATERAL_TOL_M,
                     FEASIBILITY_TOL_M, floats, flags)  # fmt: skip
    ex, ey, evx, evy, lx, lv, fx, fv = floats[: len(STATES)]
    period_ok, completing, exists = flags[0], flags[1], flags[2]
    l1_decel, f_aggressive = args[8], args[11]
    guard = np.ones(n, bool)
    done = np.flatnonzero(completing)  # the completion rule on the completing rows (few), as check_candidate
    with np.errstate(all="ignore"):
        if done.size:
            guard[done] = completion(*(a[done] for a in (ex, evx, lx, lv, l1_decel, fx, fv)), prm)
        cross_ok = guard & (exists | (not getattr(completion, "needs_evasion", False)))
        keep = np.flatnonzero(period_ok & np.where(completing, cross_ok, exists))
        parts = {name: floats[len(STATES) + j][keep] for j, name in enumerate(FLOAT_PARTS)}
        parts.update((name, flags[2 + j][keep]) for j, name in enumerate(BOOL_PARTS) if j > 0)
        sub = tuple(a[keep] for a in (ex, ey, evx, evy, lx, lv, l1_decel, fx, fv, f_aggressive))
        plan = plan_from_core(ARRAY, keep.shape, (*sub, prm.p_m, prm.p_m), exists[keep], parts, prm.p_m, prm.p_m, prm)
    ok = np.zeros(n, bool)
    ok[keep] = True
    return Verdict(ok=ok, completing=completing.copy(), plans=[(keep, plan)])
