"""Optional compiled kernel of the shield's candidate check with an own-lane leader ``L0`` (numba, extra ``fast``).

No formula lives here. :func:`check_kernel` is a loop over the rows with ``L0`` that calls, one row at a time, the
closed forms the NumPy path of ``decide._with_own`` evaluates on arrays, compiled on the float backend ``SCALAR``:
the period at the candidate (:func:`~.decide.candidate_period`), ``L0`` over it
(:func:`~safelane.safety.own_lane.own_period`), and the own-lane evasion check with its plan (:mod:`safelane.safety.
own_lane`: :func:`~safelane.safety.own_lane.member_bounds`, the bisection
:func:`~safelane.safety.own_lane._search` where a member needs it, :func:`~safelane.safety.own_lane.member_parts`,
:func:`~safelane.safety.own_lane.choose_member`). :func:`own_lane_kernel` is the evasion check alone
(:func:`~safelane.safety.own_lane.own_lane_core`'s rows). The kernels only loop, index, and decide per row whether the
bisection runs (the array path runs it on the rows that need it: the same rows, so the same bits).

**Same bits.** numba compiles without ``fastmath``, a row evaluates every candidate instant the array path
evaluates, in the same order, and the bisection takes the same ``SEARCH_STEPS`` steps from the same bracket, so
every output is bit-identical to the NumPy path's (``tests/test_fast_own.py``). The completion rule and the plans
stay :func:`~.decide.verdict_of`'s, in NumPy, on these outputs.

Imported only where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``
(:func:`~safelane.safety.evasion.fast_kernel`).
"""

from __future__ import annotations

import numpy as np
from numba import types

from ..params import Params
from ..safety import _compile
from ..safety._backend import FEASIBILITY_TOL_M, SCALAR, Limits
from ..safety._fast_base import _B, _F, announce_compiles, kernel, row_function
from ..safety.lateral import LATERAL_TOL_M, lateral_core
from ..safety.own_lane import (
    _search,
    choose_member,
    known_gaps,
    leaders_gap,
    member_parts,
    member_switch,
    needs_search,
    own_period,
)
from .decide import candidate_period, own_margin

_compile.register_rows()
announce_compiles()

#: The predicted states at the period's end (:func:`check_kernel`'s first rows of ``floats``), then ``L0``'s.
STATES = ("ex", "ey", "evx", "evy", "lx", "lv", "fx", "fv", "l0_x", "l0_v")
#: The float fields of ``own_lane_core``'s ``parts``, in the rows of the kernels' ``floats`` (after ``STATES``).
OWN_FLOATS = ("t_x1", "v_switch", "t_brake_end", "lead_gap", "follow_gap", "own_gap", "t_y_f", "t_y_switch", "y_acc_1",
              "y_acc_2", "t_y_end")  # fmt: skip
#: ``exists`` and the bool fields of ``own_lane_core``'s ``parts``, in the rows of the kernels' ``flags`` (after
#: ``period_ok`` and ``completing`` in :func:`check_kernel`'s).
OWN_FLAGS = ("exists", "lead_ok", "follow_ok", "follows_leader", "nothing", "follows_own")

_OUT = (types.Array(types.float64, 2, "C"), types.Array(types.bool_, 2, "C"))
_CHECK_SIGNATURE = types.void(*(_F,) * 11, _B, *(_F,) * 3, *(types.float64,) * 10, *_OUT)
_OWN_LANE_SIGNATURE = types.void(*(_F,) * 9, _B, *(_F,) * 6, *(types.float64,) * 5, *_OUT)


@row_function
def _member(p, v, lead, l0, l1, T, nothing, lm, om, margin_k, fp, fv, aggr, fm, prm, tol):
    """One member ``G(·, k)`` of one row (``lead``: the followed leader ``k``): ``own_lane_core``'s stacked pass for
    that row and ``k`` (:func:`~safelane.safety.own_lane.member_bounds`' pieces), the bisection only where
    :func:`~safelane.safety.own_lane.needs_search` asks for it, and the leaders' gaps at ``u_k`` only where ``u = 0``
    keeps them (the same bits: elsewhere nothing reads them)."""
    u_k = member_switch(SCALAR, p, v, lead, T, margin_k, prm, tol)
    lo = leaders_gap(SCALAR, 0.0 * u_k, p, v, lead, l0, l1, T, nothing, lm, om, prm)
    # The gaps at u_k only where u = 0 keeps the leader constraints (elsewhere no search and no use for them: lo
    # stands in, which needs_search and known_gaps read as "no")
    hi = lo if lo[0] < -tol else leaders_gap(SCALAR, u_k, p, v, lead, l0, l1, T, nothing, lm, om, prm)
    u = u_k
    if needs_search(hi[0], lo[0], tol):
        u = _search(SCALAR, u_k, p, v, lead, l0, l1, T, nothing, lm, om, prm, tol)
    at_k, at_0 = known_gaps(u_k, lo[0], hi[0], tol)
    if at_k:
        gaps = hi
    elif at_0:
        gaps = lo
    else:
        gaps = leaders_gap(SCALAR, u if lo[0] >= -tol else 0.0, p, v, lead, l0, l1, T, nothing, lm, om, prm)
    return member_parts(SCALAR, u, lo[0], gaps, p, v, lead, T, nothing, fp, fv, aggr, fm, prm, tol)


@row_function
def _own_lane(p, py, v, vy, p1, v1, d1, fp, fv, aggr, p0, v0, d0, lm, fm, om, prm, tol):
    """One row of :func:`~safelane.safety.own_lane.own_lane_core`: ``(floats, flags)`` in the orders of
    :data:`OWN_FLOATS` and :data:`OWN_FLAGS`."""
    T, t_y1, y_acc_1, y_acc_2, t_y_end = lateral_core(SCALAR, py, vy, prm)
    nothing = T <= 0.0
    l1, l0 = (p1, v1, d1), (p0, v0, d0)
    via_l1 = _member(p, v, l1, l0, l1, T, nothing, lm, om, lm, fp, fv, aggr, fm, prm, tol)
    # Where following L1 evades, choose_member takes that member whatever the other's fields: L0's is not needed
    # (the array path computes it and discards it; the same bits)
    via_l0 = via_l1 if via_l1[0] else _member(p, v, l0, l0, l1, T, nothing, lm, om, om, fp, fv, aggr, fm, prm, tol)
    # r: exists, follows_own, lead_ok, follow_ok, t_x1, v_switch, t_brake_end, follows_leader, lead_gap, follow_gap,
    # own_gap
    r = choose_member(SCALAR, via_l1, via_l0)
    return (r[4], r[5], r[6], r[8], r[9], r[10], T, t_y1, y_acc_1, y_acc_2, t_y_end), (r[0], r[2], r[3], r[7], nothing,
                                                                                        r[1])  # fmt: skip


@kernel(_CHECK_SIGNATURE)
def check_kernel(
    ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggr, l0_x, l0_v, l0_decel, a_a, a_d,
    a_ym, y_safe, p_m, dt, level, lat_tol, tol, margin, floats, flags,
):  # fmt: skip
    """Per row with ``L0``: ``floats`` ``(21, n)`` — :data:`STATES`, then :data:`OWN_FLOATS`; ``flags`` ``(8, n)`` —
    ``period_ok``, ``completing``, then :data:`OWN_FLAGS`. ``margin``: the margin to ``L0`` on the evasion."""
    prm = Limits(a_a, a_d, a_ym, y_safe)
    for i in range(floats.shape[1]):
        state, period_ok, completing = candidate_period(
            SCALAR, ego_x[i], ego_y[i], ego_vx[i], ego_vy[i], a_x[i], a_y[i], l1_x[i], l1_v[i], l1_decel[i], f_x[i],
            f_v[i], f_aggr[i], prm, p_m, dt, level, lat_tol, tol,
        )  # fmt: skip
        period_ok, completing, ox, ov = own_period(
            SCALAR, ego_x[i], ego_vx[i], a_x[i], l0_x[i], l0_v[i], l0_decel[i], period_ok, completing, state[3], p_m,
            dt, tol,
        )  # fmt: skip
        f, b = _own_lane(state[0], state[1], state[2], state[3], state[4], state[5], l1_decel[i], state[6], state[7],
                         f_aggr[i], ox, ov, l0_decel[i], p_m, p_m, margin, prm, tol)  # fmt: skip
        for j in range(8):
            floats[j, i] = state[j]
        floats[8, i] = ox
        floats[9, i] = ov
        for j in range(11):
            floats[10 + j, i] = f[j]
        flags[0, i] = period_ok
        flags[1, i] = completing
        for j in range(6):
            flags[2 + j, i] = b[j]


@kernel(_OWN_LANE_SIGNATURE)
def own_lane_kernel(
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, l0_p, l0_v, l0_decel, lead_margin,
    follow_margin, margin, a_a, a_d, a_ym, y_safe, tol, floats, flags,
):  # fmt: skip
    """Per row: :func:`~safelane.safety.own_lane.own_lane_core`'s ``floats`` ``(11, n)`` in the order of
    :data:`OWN_FLOATS`, ``flags`` ``(6, n)`` in that of :data:`OWN_FLAGS`."""
    prm = Limits(a_a, a_d, a_ym, y_safe)
    for i in range(floats.shape[1]):
        f, b = _own_lane(ego_px[i], ego_py[i], ego_vx[i], ego_vy[i], l1_p[i], l1_v[i], l1_decel[i], f_p[i], f_v[i],
                         aggressive[i], l0_p[i], l0_v[i], l0_decel[i], lead_margin[i], follow_margin[i], margin[i], prm,
                         tol)  # fmt: skip
        for j in range(11):
            floats[j, i] = f[j]
        for j in range(6):
            flags[j, i] = b[j]


def _rows(arrays, aggressive_at: int):
    """The kernels' inputs: 1-D read-only float64 views of one length (bool at ``aggressive_at``), and that length."""
    arrays = [np.asarray(a, dtype=np.bool_ if j == aggressive_at else np.float64) for j, a in enumerate(arrays)]
    n = max(a.size for a in arrays)
    return [np.broadcast_to(a.reshape(-1) if a.size == n else a, (n,)) for a in arrays], n


def _parts(floats, flags) -> tuple[np.ndarray, dict]:
    """``(exists, parts)`` as :func:`~safelane.safety.own_lane.own_lane_core` returns them, from a kernel's rows."""
    parts = {name: floats[j] for j, name in enumerate(OWN_FLOATS)}
    parts.update((name, flags[j]) for j, name in enumerate(OWN_FLAGS) if j > 0)
    return flags[0], parts


def check_own(args, own, prm: Params, level: float):
    """``decide._with_own``'s NumPy block for the rows with ``L0``, compiled (:func:`check_kernel`): ``args`` the
    candidate check's 12 arguments (``ego_x … f_aggressive``), ``own`` ``(l0_x, l0_v, l0_decel)``, ``level`` the
    completion level there. Returns ``(state, period_ok, completing, (l0_x', l0_v'), exists, parts)``: the predicted
    states, the period's verdict (with ``L0``'s gap over it), whether the step completes (moving away from ``L0``),
    ``L0``'s worst case at the period's end, and ``own_lane_core``'s ``(exists, parts)`` from the predicted state —
    the NumPy path's bits."""
    rows, n = _rows((*args, *own), 11)
    floats = np.empty((len(STATES) + len(OWN_FLOATS), n))
    flags = np.empty((2 + len(OWN_FLAGS), n), dtype=np.bool_)
    check_kernel(*rows, prm.a_x_a, prm.a_x_d, prm.a_y_m, prm.y_safe, prm.p_m, prm.dt, level, LATERAL_TOL_M,
                 FEASIBILITY_TOL_M, own_margin(prm), floats, flags)  # fmt: skip
    exists, parts = _parts(floats[len(STATES) :], flags[2:])
    return tuple(floats[:8]), flags[0], flags[1], (floats[8], floats[9]), exists, parts


def own_lane_rows(
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, l0_p, l0_v, l0_decel, lead_margin,
    follow_margin, own_margin, prm: Params, tol: float = FEASIBILITY_TOL_M,
):  # fmt: skip
    """:func:`~safelane.safety.own_lane.own_lane_core` (same arguments, ``(exists, parts)`` of shape ``(n,)``),
    compiled (:func:`own_lane_kernel`)."""
    rows, n = _rows((ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, l0_p, l0_v, l0_decel,
                     lead_margin, follow_margin, own_margin), 9)  # fmt: skip
    floats = np.empty((len(OWN_FLOATS), n))
    flags = np.empty((len(OWN_FLAGS), n), dtype=np.bool_)
    own_lane_kernel(*rows, prm.a_x_a, prm.a_x_d, prm.a_y_m, prm.y_safe, tol, floats, flags)
    return _parts(floats, flags)
