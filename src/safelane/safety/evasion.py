"""Does a safe evasion trajectory exist? (paper Eq. 9 and the check that closes §3.3).

The ego returns laterally on the fastest profile (Eq. 5, :mod:`.lateral`) while moving longitudinally on the
optimal profile behind ``L1`` (Eqs. 6–8, :mod:`.longitudinal`). The follower ``F`` does its worst (Eq. 9):
an aggressive one accelerates at ``a_x_a``; a collaborative one brakes at ``a_x_d`` until it stops. The
evasion exists when ``p(t) − p_f(t) >= p_m`` for all ``t ∈ [0, t_y_f]``, evaluated **exactly**: the
difference is piecewise quadratic, so its minimum is at ``0``, ``t_y_f``, a breakpoint (``t_x1``, ``t_x2``,
the follower's stop) or a stationary point where the speeds are equal (accelerating ego vs braking
follower: ``(v_f − v)/(a_x_a + a_x_d)``; ego following ``L1`` vs braking follower:
``(v_f − v_1)/(a_x_d − a_x_1_d)``). Evaluating the difference at every such candidate clipped to
``[0, t_y_f]`` gives the exact minimum (extra candidates are harmless: they are points of the interval).
The longitudinal profile is the position-maximal one at every instant, so if it fails against ``F``,
every admissible profile does.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..params import Params
from ._backend import ARRAY, jitable
from ._checks import bool_array, check_params, finish, prepare
from .chain import braked_position, decel_cap
from .lateral import lateral_core
from .longitudinal import FEASIBILITY_TOL_M, ego_position, longitudinal_core
from .plan import EvasionPlan, check_broadcasts, plan_from_core


def follower_offset(xp, t, f_p, f_v, aggressive, prm: Params, f_stop=None):
    """Backend-generic core of :func:`follower_position`; ``f_stop`` is the collaborative follower's stop time
    ``xp.stop_time(f_v, a_x_d)``, computed here unless given."""
    aggressive_pos = f_p + f_v * t + 0.5 * prm.a_x_a * t * t
    return xp.where(aggressive, aggressive_pos, braked_position(xp, f_p, f_v, prm.a_x_d, t, f_stop))


def follower_position(p, v, aggressive, t, params: Params):
    """Worst-case follower position at ``t`` (Eq. 9): aggressive accelerates at ``a_x_a``, collaborative
    brakes at ``a_x_d`` until it stops. Arguments broadcast; ``v >= 0``, ``t >= 0``."""
    check_params(params)
    xp, a, shape = prepare({"p": p, "v": v, "aggressive": aggressive, "t": t}, nonneg=("v", "t"), bools=("aggressive",))
    with np.errstate(all="ignore"):
        out = follower_offset(xp, a["t"], a["p"], a["v"], a["aggressive"], params)
    return finish(xp, shape, out)


_PLAN_INPUTS = ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "f_p", "f_v")


#: The fields of an evasion check's plan, in the order :func:`evasion_parts` returns them after ``exists``.
PARTS = (
    "t_y_f", "t_y_switch", "y_acc_1", "y_acc_2", "t_y_end", "t_x1", "v_switch", "t_brake_end", "lead_gap", "follow_gap",
    "lead_ok", "follow_ok", "nothing", "follows_leader",
)  # fmt: skip


def evasion_parts(
    xp,
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
    prm,
    tol=FEASIBILITY_TOL_M,
):
    """The evasion check of Eq. 9 with its plan, backend-generic: the one source of the check (NumPy arrays on
    ``ARRAY``, Python floats on ``SCALAR``, one row of a compiled kernel in :mod:`._fast`).

    Returns ``(exists, t_y_f, t_y_switch, y_acc_1, y_acc_2, t_y_end, t_x1, v_switch, t_brake_end, lead_gap,
    follow_gap, lead_ok, follow_ok, nothing, follows_leader)``: ``exists`` then the fields named by :data:`PARTS`.
    ``prm`` is a :class:`~safelane.Params` or its :class:`~._backend.Limits`.
    """
    T, t_y1, y_acc_1, y_acc_2, t_y_end = lateral_core(xp, ego_py, ego_vy, prm)
    lead_ok, u, V, t2, match, lead_gap = longitudinal_core(
        xp, ego_px, ego_vx, l1_p, l1_v, l1_decel, T, lead_margin, prm, tol
    )
    a_a, a_d = prm.a_x_a, prm.a_x_d
    l1_stop = xp.stop_time(l1_v, l1_decel)
    f_stop = xp.stop_time(f_v, a_d)
    # The follower gap's exact minimum over [0, T]: its value at every candidate clipped to [0, T] (module docstring).
    follow_gap = _follow_gap_at(
        xp, 0.0 * T, T, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, follow_margin,
        prm, l1_stop, f_stop,
    )  # fmt: skip
    for c in (u, t2, f_stop, xp.div(f_v - ego_vx, a_a + a_d, 0.0), xp.div(f_v - l1_v, a_d - l1_decel, 0.0), T):
        gap = _follow_gap_at(
            xp, c, T, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, follow_margin,
            prm, l1_stop, f_stop,
        )  # fmt: skip
        follow_gap = xp.minimum(follow_gap, gap)
    follow_ok = follow_gap >= -tol
    nothing = T <= 0.0
    exists = nothing | (lead_ok & follow_ok)
    return (
        exists, T, t_y1, y_acc_1, y_acc_2, t_y_end, u, V, t2, lead_gap, follow_gap, lead_ok, follow_ok, nothing, match
    )  # fmt: skip


def _follow_gap_at(
    xp, c, T, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, margin, prm, l1_stop, f_stop
):
    """``p(t) − p_f(t) − margin`` at ``t = clip(c, 0, T)`` (Eq. 9's worst-case follower)."""
    t = xp.clip(c, 0.0, T)
    ego = ego_position(xp, t, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, prm, l1_stop)
    return ego - follower_offset(xp, t, f_p, f_v, aggressive, prm, f_stop) - margin


def evasion_core(
    xp,
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
    prm: Params,
    tol: float = FEASIBILITY_TOL_M,
):
    """:func:`evasion_parts` as ``(exists, parts)``, ``parts`` a dict of the plan's fields (:data:`PARTS`); used by
    :func:`plan_evasion`, :func:`evasion_exists` and the shield.

    NumPy batches of :data:`FAST_PLAN_MIN` elements or more run the compiled kernel (:mod:`._fast`: the same function
    compiled, one row at a time) where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``; smaller ones and every
    batch without numba evaluate it on NumPy arrays.
    """
    args = (ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v, aggressive, lead_margin, follow_margin)
    if xp is ARRAY:
        shape = np.broadcast_shapes(*(np.shape(a) for a in args))
        if math.prod(shape) >= FAST_PLAN_MIN and (kernel := fast_kernel()) is not None:
            return kernel.run_plan(args, shape, prm, tol)
    exists, *fields = evasion_parts(xp, *args, prm, tol)
    return exists, dict(zip(PARTS, fields, strict=True))


def _prepare_evasion(
    ego_px,
    ego_py,
    ego_vx,
    ego_vy,
    l1_p,
    l1_v,
    l1_decel,
    f_p,
    f_v,
    follower_aggressive,
    params,
    leader_human,
    follower_human,
):
    check_params(params)
    values = dict(zip(_PLAN_INPUTS, (ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel, f_p, f_v), strict=False))
    values.update(follower_aggressive=follower_aggressive, leader_human=leader_human, follower_human=follower_human)
    xp, a, shape = prepare(
        values,
        nonneg=("ego_vx", "l1_v", "l1_decel", "f_v"),
        bools=("follower_aggressive", "leader_human", "follower_human"),
        upper={"l1_decel": decel_cap(params)},
    )
    lead_margin = xp.where(a["leader_human"], params.p_m_human, params.p_m)
    follow_margin = xp.where(a["follower_human"], params.p_m_human, params.p_m)
    args = (*tuple(a[k] for k in _PLAN_INPUTS), a["follower_aggressive"], lead_margin, follow_margin)
    return xp, args, shape, lead_margin, follow_margin


def evasion_exists(
    ego_px,
    ego_py,
    ego_vx,
    ego_vy,
    l1_p,
    l1_v,
    l1_decel,
    f_p,
    f_v,
    follower_aggressive,
    params: Params,
    *,
    leader_human=False,
    follower_human=False,
):
    """True where a safe evasion trajectory back to the original lane exists in the worst case.

    Args (all broadcast to one batch shape):
        ego_px, ego_py, ego_vx, ego_vy: ego state (``ego_vx >= 0``; ``ego_vy`` positive toward the target lane).
        l1_p, l1_v, l1_decel: ``L1``'s position, speed and worst-case deceleration (``[0, max(a_x_d, a_o_d)]``,
            e.g. from :func:`worst_case_leader_decel`; above ``a_x_d`` the ego never follows ``L1``).
        f_p, f_v: follower position and speed.
        follower_aggressive: bool; the follower's assumed worst case (Eq. 9).
        leader_human, follower_human: keep ``p_m_human`` instead of ``p_m`` to that vehicle (footnote 1).

    Returns a bool array of the batch shape (a NumPy bool scalar for scalar inputs). Gaps within
    ``FEASIBILITY_TOL_M`` of the margin count as kept. NumPy batches of ``FAST_MIN_BATCH`` elements or more run
    through the compiled kernel of :mod:`._fast` where numba is installed (the same bits; ``SAFELANE_NO_NUMBA=1``
    keeps the NumPy path).
    """
    xp, args, shape, *_ = _prepare_evasion(
        ego_px,
        ego_py,
        ego_vx,
        ego_vy,
        l1_p,
        l1_v,
        l1_decel,
        f_p,
        f_v,
        follower_aggressive,
        params,
        leader_human,
        follower_human,
    )
    size = math.prod(shape)
    if xp is ARRAY and size >= FAST_MIN_BATCH:
        kernel = fast_kernel()
        if kernel is not None:
            return kernel.run(args, shape, params, FEASIBILITY_TOL_M)
    if xp is ARRAY and size > CHUNK:
        return _exists_chunked(args, shape, params)
    with np.errstate(all="ignore"):
        exists, _ = evasion_core(xp, *args, params)
    return finish(xp, shape, exists, np.bool_)


#: Batches larger than this many elements are checked ``CHUNK`` elements at a time. The core makes a few
#: hundred element-wise temporaries; in chunks they stay in cache, and at 64 KiB each they stay below glibc's
#: 128 KiB ``mmap`` threshold (larger blocks are mapped and unmapped, page fault by page fault, every time).
#: That makes a batch of a million about twice as fast as one pass. The arithmetic is unchanged.
CHUNK = 8192


#: NumPy batches of at least this many elements go to the compiled kernel (:mod:`._fast`, extra ``fast``) when numba
#: is installed and ``SAFELANE_NO_NUMBA`` is not ``1``; smaller ones, and every batch without numba, take the NumPy
#: path, which stays the reference. The kernel's verdicts and gaps are bit-identical to it
#: (``tests/test_fast_core.py``).
FAST_MIN_BATCH = 4096

_FAST: list = []  # the imported kernel module, or None once numba failed to import (tried once per process)


def fast_kernel():
    """The compiled kernel module :mod:`._fast`, or ``None`` (numba missing, or ``SAFELANE_NO_NUMBA=1``). The first
    call imports numba and compiles the kernel or loads it from numba's on-disk cache."""
    if os.environ.get("SAFELANE_NO_NUMBA", "") == "1":
        return None
    if not _FAST:
        try:
            from . import _fast
        except ImportError:
            _fast = None
        _FAST.append(_fast)
    return _FAST[0]


#: :func:`evasion_core` runs the compiled plan kernel (:func:`._fast.plan_kernel`) for NumPy batches of at least this
#: many elements, i.e. every non-empty one: measured at 1, 4, 16 and 31 rows (idle 2-core machine), the kernel's call
#: took 63–79 µs and the NumPy path 650–690 µs (a few hundred array operations). The threshold was 32 before.
FAST_PLAN_MIN = 1


def _exists_chunked(args, shape, params: Params) -> np.ndarray:
    flat = [a if a.ndim == 0 else np.broadcast_to(a, shape).reshape(-1) for a in args]
    out = np.empty(math.prod(shape), dtype=bool)
    with np.errstate(all="ignore"):
        for start in range(0, out.size, CHUNK):
            chunk = [a if a.ndim == 0 else a[start : start + CHUNK] for a in flat]
            out[start : start + CHUNK], _ = evasion_core(ARRAY, *chunk, params)
    return out.reshape(shape)


def plan_evasion(
    ego_px,
    ego_py,
    ego_vx,
    ego_vy,
    l1_p,
    l1_v,
    l1_decel,
    f_p,
    f_v,
    follower_aggressive,
    params: Params,
    *,
    chain_unsafe=False,
    leader_human=False,
    follower_human=False,
) -> EvasionPlan:
    """Like :func:`evasion_exists`, but returns the full :class:`EvasionPlan` with reasons and switch times.

    ``chain_unsafe`` (bool, batch-broadcastable) only sets the informational ``CHAIN_UNSAFE`` reason bit.
    """
    xp, args, shape, lead_margin, follow_margin = _prepare_evasion(
        ego_px,
        ego_py,
        ego_vx,
        ego_vy,
        l1_p,
        l1_v,
        l1_decel,
        f_p,
        f_v,
        follower_aggressive,
        params,
        leader_human,
        follower_human,
    )
    chain_unsafe = bool_array("chain_unsafe", chain_unsafe)
    if check_broadcasts("chain_unsafe", chain_unsafe.shape, shape) != shape:
        raise ValueError(f"chain_unsafe of shape {chain_unsafe.shape} must broadcast to the batch shape {shape}")
    with np.errstate(all="ignore"):
        exists, parts = evasion_core(xp, *args, params)
    return plan_from_core(xp, shape, args, exists, parts, lead_margin, follow_margin, params, chain_unsafe)


# The closed forms compiled into the kernels (safety/_compile.py): the same functions, evaluated row by row.
jitable(follower_offset, evasion_parts, _follow_gap_at)
