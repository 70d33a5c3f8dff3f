"""Optional compiled kernel of :func:`~.evasion.evasion_core` with the whole plan (numba; extra ``fast``).

:func:`plan_kernel` is :func:`~._fast.exists_kernel`'s arithmetic evaluated in full for every element — the
lateral profile of Eq. 5 (:func:`~.lateral.lateral_core`: ``t_y_f``, the switch, both accelerations, the end), the
switch time of Eqs. 6–8 and its leader gap (:func:`~.longitudinal.longitudinal_core`), the profile after it
(:func:`~.longitudinal.profile`) and the follower gap of Eq. 9 — and writes every field of ``evasion_core``'s
``parts``: what the shield needs to hold a plan, not only the verdict. The shield checks every candidate action of
every period through it (``decide.check_candidate``), so this is the closed loop's evasion check.

**Same bits** as the NumPy path, for the reasons :mod:`._fast` gives (its helpers, the same evaluation order, no
``fastmath``); ``tests/test_fast_plan.py`` compares every field, not only the verdict. The NumPy path stays the
reference and the fallback (``SAFELANE_NO_NUMBA=1``, numba missing, or batches below
:data:`~.evasion.FAST_PLAN_MIN`).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types

from ._fast import _B, _F, _braked, _follow_min, _leader_gap_min, _leader_search, _profile, _sqrt, _stop_time
from ._fast_base import announce_compile

announce_compile(__file__)

_PLAN_SIGNATURE = types.void(
    *(_F,) * 9, _B, _F, _F, *(types.float64,) * 6, types.Array(types.float64, 2, "C"), types.Array(types.bool_, 2, "C")
)

#: The float fields of ``evasion_core``'s parts, in the rows of :func:`plan_kernel`'s ``floats`` output.
FLOAT_PARTS = (
    "t_y_f", "t_y_switch", "y_acc_1", "y_acc_2", "t_y_end", "t_x1", "v_switch", "t_brake_end", "lead_gap", "follow_gap"
)  # fmt: skip
#: ``exists`` and the bool fields of the parts, in the rows of :func:`plan_kernel`'s ``flags`` output.
BOOL_PARTS = ("exists", "lead_ok", "follow_ok", "nothing", "follows_leader")


@numba.njit(error_model="numpy", nogil=True)
def _plan_parts(py, vy, p, v, p1, v1, a1, fp, fv, aggr, margin, fmargin, a_a, a_d, a_y, y_safe, lat_tol, tol):
    """One element of :func:`plan_kernel`: ``(floats, flags)`` as tuples in the orders of :data:`FLOAT_PARTS` and
    :data:`BOOL_PARTS`."""
    s = a_a + a_d
    # lateral_core (Eq. 5), every output
    e = py - y_safe
    sl = e + vy * abs(vy) / (2.0 * a_y)
    nothing = (e <= lat_tol) and ((vy <= 0.0) or (sl <= lat_tol))
    above = sl > 0.0
    r = _sqrt(a_y * e + 0.5 * vy * vy)
    t_bb = (vy + 2.0 * r) / a_y
    if nothing:
        T = 0.0
    elif above:
        T = t_bb
    else:
        T = (-vy - _sqrt(vy * vy - 2.0 * a_y * e)) / a_y
    t_1 = (vy + r) / a_y if above else 0.0
    acc_1 = -a_y if above else 0.0
    acc_2 = (-a_y if vy > 0.0 else a_y) if nothing else a_y
    t_end = t_bb if above else abs(vy) / a_y
    # longitudinal_core (Eqs. 6-8): feasibility from u = 0, then the largest feasible switch time
    d0 = p1 - p - margin
    l1_stop = _stop_time(v1, a1)
    l1_at_T = _braked(p1, v1, a1, T, l1_stop)
    gap0 = _leader_gap_min(0.0 * T, T, d0, p, v, p1, v1, a1, margin, a_a, a_d, l1_stop, l1_at_T)
    lead_ok = gap0 >= -tol
    u, lead_gap = _leader_search(T, gap0, d0, p, v, p1, v1, a1, margin, a_a, a_d, s, s * a_a, l1_stop, l1_at_T, tol)
    V, t2, match = _profile(u, v, v1, a1, a_a, a_d, l1_stop)
    # the follower (Eq. 9)
    fgap = _follow_min(T, p, v, u, V, t2, match, p1, v1, a1, fp, fv, aggr, fmargin, a_a, a_d, s, l1_stop, tol, False)
    follow_ok = fgap >= -tol
    floats = (T, t_1, acc_1, acc_2, t_end, u, V, t2, lead_gap, fgap)
    flags = ((T <= 0.0) or (lead_ok and follow_ok), lead_ok, follow_ok, T <= 0.0, match)
    return floats, flags


@numba.njit(_PLAN_SIGNATURE, cache=True, nogil=True)
def plan_kernel(
    ego_px,
    ego_py,
    ego_vx,
    ego_vy,
    l1_p,
    l1_v,
    l1_decel,
    f_p,
    f_v,
    aggressive,
    lead_margin,
    follow_margin,
    a_a,
    a_d,
    a_y,
    y_safe,
    lat_tol,
    tol,
    floats,
    flags,
):
    """Write :func:`~.evasion.evasion_core`'s ``exists`` and ``parts`` for each element: ``floats`` ``(10, n)`` in
    the order of :data:`FLOAT_PARTS`, ``flags`` ``(5, n)`` in that of :data:`BOOL_PARTS`. Inputs as
    :func:`~._fast.exists_kernel`'s."""
    for i in range(floats.shape[1]):
        f, b = _plan_parts(
            ego_py[i], ego_vy[i], ego_px[i], ego_vx[i], l1_p[i], l1_v[i], l1_decel[i], f_p[i], f_v[i], aggressive[i],
            lead_margin[i], follow_margin[i], a_a, a_d, a_y, y_safe, lat_tol, tol,
        )  # fmt: skip
        for j in range(10):
            floats[j, i] = f[j]
        for j in range(5):
            flags[j, i] = b[j]


def run_plan(args, shape, params, tol: float, lat_tol: float):
    """:func:`plan_kernel` on ``evasion_core``'s argument tuple (arrays broadcastable to ``shape``): returns
    ``(exists, parts)`` as ``evasion_core`` does, every array of ``shape``."""
    n = math.prod(shape)
    flat = []
    for j, a in enumerate(args):
        a = np.asarray(a, dtype=np.bool_ if j == 9 else np.float64)
        flat.append(np.broadcast_to(a, (n,)) if a.size == 1 else np.broadcast_to(a, shape).reshape(-1))
    floats = np.empty((len(FLOAT_PARTS), n))
    flags = np.empty((len(BOOL_PARTS), n), dtype=np.bool_)
    plan_kernel(*flat, params.a_x_a, params.a_x_d, params.a_y_m, params.y_safe, lat_tol, tol, floats, flags)
    parts = {name: floats[j].reshape(shape) for j, name in enumerate(FLOAT_PARTS)}
    parts.update((name, flags[j].reshape(shape)) for j, name in enumerate(BOOL_PARTS[1:], start=1))
    return flags[0].reshape(shape), parts
