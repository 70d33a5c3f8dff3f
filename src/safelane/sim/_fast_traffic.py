"""Optional compiled kernels of the paper's traffic and the chain scan (numba, extra ``fast``): loops and indexing only.

No rule lives here. Each kernel is a loop over rows that calls the closed forms of the modules that own the rules,
compiled on the float backend ``SCALAR`` (:mod:`safelane.safety._compile`): :func:`leader_kernel` calls
:func:`~.behaviours.leader_want`, :func:`~.behaviours.leader_confirmed` and :func:`~.behaviours.leader_keep` for
each acting connected leader (:func:`~.behaviours.link_decel` and :func:`~.behaviours.violation_accel` where it
violates), :func:`follower_kernel` :func:`~.behaviours.follower_wish_core` and :func:`~.behaviours.follow_core`,
:func:`chain_kernel` :func:`safelane.safety.chain.chain_link` link by link. The NumPy functions
(:func:`~.behaviours.leader_accels`, :func:`~.behaviours.follower_accel`, :func:`safelane.safety.chain.propagate_chain`)
evaluate the very same functions on arrays; numba compiles without ``fastmath`` and in the source's order, so the
kernels give their bits (``tests/test_fast_traffic.py``). Where the NumPy path selects with a mask or ``where``
(the exact check where :func:`~.behaviours.leader_needs_check`, the violation's draw, F's follow of the ego where
:func:`~.behaviours.follows_ego`), a row branches instead and skips what the NumPy path discards: measured on the
closed loop, evaluating both sides per row made it about a quarter slower. The row functions :func:`_leader_row`,
:func:`_follower_row` and :func:`_chain_row` are what the compiled closed loop (:mod:`._fast_loop`) calls too.
"""

from __future__ import annotations

import numpy as np
from numba import types

from ..params import Params
from ..safety import _compile
from ..safety._backend import INF, SCALAR
from ..safety._fast_base import announce_compiles, kernel, row_function
from ..safety.chain import chain_link
from ..tolerances import TIME_TOL_S
from .behaviours import (
    follow_core,
    follower_wish_core,
    follows_ego,
    gap_ratio,
    leader_confirmed,
    leader_keep,
    leader_needs_check,
    leader_want,
    link_decel,
    violation_accel,
    wave_level,
    wave_wish,
)
from .traffic import profile_after, profile_end, profile_scan

_compile.register_rows()
announce_compiles()

_M = types.Array(types.float64, 2, "A", readonly=True)
_MB = types.Array(types.bool_, 2, "A", readonly=True)
_V = types.Array(types.float64, 1, "A", readonly=True)
_SIGNATURE = types.void(
    _M, _M, _M, _MB, _MB, _M, _M, _V, _V, types.boolean, _MB, _M, *(types.float64,) * 2,
    types.Array(types.float64, 2, "F"),
)  # fmt: skip


@row_function
def _leader_row(slack, v_f, v_l, d, own, task, violating, pick, decel_last, a_o, dt):
    """One acting connected leader: ``slack`` to the vehicle ahead, that vehicle's bound ``d``, its own ``own``."""
    if violating:  # the NumPy path's where: the draw replaces the rule
        return violation_accel(SCALAR, link_decel(SCALAR, slack, v_f, v_l, d, a_o), decel_last, pick)
    want = leader_want(SCALAR, slack, v_f, v_l, d, own, task, dt)
    ok = True
    if leader_needs_check(SCALAR, own, d):  # the NumPy path's mask: the exact check only where it is needed
        ok = leader_confirmed(SCALAR, want, slack, v_f, v_l, d, own, dt)
    return leader_keep(SCALAR, want, ok, own)


@kernel(_SIGNATURE)
def leader_kernel(x, v, margin, is_last, acts, bounds, task, a_last, decel_last, any_violation, violating, pick, a_o,
                  dt, acc):  # fmt: skip
    """Write :func:`~.behaviours.leader_accels`' accelerations into ``acc`` (``(B, K)``, zero on entry). Inputs as
    that function's; ``violating``/``pick`` are read only where ``any_violation``."""
    bsz, k = x.shape
    for i in range(1, k - 1):  # followers are slots 1..K-2, each behind the next slot (column by column: F order)
        for b in range(bsz):
            if not acts[b, i]:
                continue
            breaks = any_violation and violating[b, i]
            acc[b, i] = _leader_row(
                x[b, i + 1] - x[b, i] - margin[b, i], v[b, i], v[b, i + 1], bounds[b, i + 1], bounds[b, i],
                task[b, i], breaks, pick[b, i] if breaks else 0.0, decel_last[b], a_o, dt,
            )  # fmt: skip
    for i in range(k):
        for b in range(bsz):
            if is_last[b, i]:
                acc[b, i] = a_last[b]


def leader_accels(x, v, margin, roles, bounds, task, a_last, decel_last, violating, violate_pick, prm: Params):
    """:func:`leader_kernel` with :func:`~.behaviours.leader_accels`' arguments and result (``(B, K)``, F order)."""
    is_last, acts = roles
    bsz, k = x.shape
    any_violation = violating is not None
    if not any_violation:
        violating, violate_pick = np.zeros((1, 1), bool), np.zeros((1, 1))
    args = [np.asarray(a, dtype=np.float64) for a in (x, v, margin)]
    args += [np.asarray(a, dtype=np.bool_) for a in (is_last, acts)]
    args += [np.asarray(a, dtype=np.float64) for a in (bounds, task)]
    args += [np.broadcast_to(np.asarray(a, dtype=np.float64), (bsz,)) for a in (a_last, decel_last)]
    acc = np.zeros((bsz, k), order="F")
    leader_kernel(*args, any_violation, np.asarray(violating, dtype=np.bool_),
                  np.asarray(violate_pick, dtype=np.float64), prm.others_decel, prm.dt, acc)  # fmt: skip
    return acc


_R = types.Array(types.float64, 1, "A", readonly=True)
_RB = types.Array(types.bool_, 1, "A", readonly=True)
_FOLLOWER_SIGNATURE = types.void(
    *(_R,) * 6, _RB, _RB, _R, types.boolean, _R, types.boolean, *(types.float64,) * 6,
    types.Array(types.float64, 1, "C"),
)  # fmt: skip


@row_function
def _follower_row(f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, completed, gap0, has_wanted, wanted, ignores_ego,
                  p_m, a_x_a, a_o, open_decel, open_gap_m, dt):  # fmt: skip
    """F's acceleration: a hook's ``wanted`` where ``has_wanted``, else its nominal wish."""
    if not has_wanted:
        wanted = follower_wish_core(SCALAR, f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, gap0, p_m, a_x_a, a_o,
                                    open_decel, open_gap_m)  # fmt: skip
    a = follow_core(SCALAR, wanted, l1_x - f_x - p_m, f_v, l1_v, a_o, dt)
    if follows_ego(SCALAR, ego_x - f_x, aggressive, completed, ignores_ego):  # the NumPy path's where
        a = follow_core(SCALAR, a, ego_x - f_x - p_m, f_v, ego_vx, a_o, dt)
    return a


@kernel(_FOLLOWER_SIGNATURE)
def follower_kernel(f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, completed, gap0, has_wanted, wanted, ignores_ego,
                    p_m, a_x_a, a_o, open_decel, open_gap_m, dt, out):  # fmt: skip
    """:func:`~.behaviours.follower_accel` per scenario into ``out``; ``wanted`` is read only where ``has_wanted``."""
    for i in range(out.shape[0]):
        out[i] = _follower_row(
            f_x[i], f_v[i], l1_x[i], l1_v[i], ego_x[i], ego_vx[i], aggressive[i], completed[i], gap0[i], has_wanted,
            wanted[i], ignores_ego, p_m, a_x_a, a_o, open_decel, open_gap_m, dt,
        )  # fmt: skip


def follower_accel(f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, completed, gap0, prm: Params, open_decel: float,
                   open_gap_m: float, wanted=None, ignores_ego: bool = False):  # fmt: skip
    """:func:`follower_kernel` with :func:`~.behaviours.follower_accel`'s arguments and result."""
    floats = [np.asarray(a, dtype=np.float64) for a in (f_x, f_v, l1_x, l1_v, ego_x, ego_vx)]
    n = floats[0].shape[0]
    r = lambda a, dtype=np.float64: np.broadcast_to(np.asarray(a, dtype=dtype), (n,))  # noqa: E731
    out = np.empty(n)
    follower_kernel(
        *(r(a) for a in floats), r(aggressive, np.bool_), r(completed, np.bool_), r(gap0), wanted is not None,
        r(0.0 if wanted is None else wanted), bool(ignores_ego), prm.p_m, prm.a_x_a, prm.others_decel,
        float(open_decel), float(open_gap_m), prm.dt, out,
    )  # fmt: skip
    return out


_CHAIN_SIGNATURE = types.void(
    _M, _M, _M, _M, types.float64, types.Array(types.float64, 2, "F"), types.Array(types.bool_, 1, "C")
)


@row_function
def _chain_row(x, v, r, promise, margin, col, a_o, bounds):
    """One scenario of :func:`chain_kernel`: row ``r`` of ``x``, ``v`` and ``bounds`` (``(., K)``), column ``col`` of
    ``promise``, ``margin`` (``(N, .)``); writes ``bounds[r]``, returns ``unsafe``."""
    k = x.shape[1]
    a_ahead = a_o
    unsafe = False
    bounds[r, 0] = a_o
    bounds[r, k - 1] = a_o
    for i in range(k - 3, -1, -1):  # link i: L(i+1) behind L(i+2), slots i+1 and i+2
        slack = x[r, i + 2] - x[r, i + 1] - margin[i, col]
        _, a_ahead, broken = chain_link(SCALAR, slack, v[r, i + 1], v[r, i + 2], a_ahead, promise[i, col], a_o)
        unsafe = unsafe | broken
        bounds[r, i + 1] = a_ahead
    return unsafe


@kernel(_CHAIN_SIGNATURE)
def chain_kernel(x, v, promise, margin, a_o, bounds, unsafe):
    """:meth:`~.step.ClosedLoop.chain` per scenario: the scan of :func:`safelane.safety.chain.propagate_chain` from
    ``L(N+1)`` (``a_o``) down to ``L1`` into ``bounds`` (``(B, K)``, F's slot ``a_o``) and ``unsafe``.
    ``promise``, ``margin``: ``(N, B)`` rows of the links ``L1..LN``."""
    for b in range(x.shape[0]):
        unsafe[b] = _chain_row(x, v, b, promise, margin, b, a_o, bounds)


def chain_bounds(x, v, promise, margin, prm: Params):
    """:func:`chain_kernel`: ``(bounds (B, K), unsafe (B,))``."""
    bsz, k = x.shape
    bounds = np.empty((bsz, k), order="F")
    unsafe = np.empty(bsz, dtype=np.bool_)
    chain_kernel(x, v, promise.reshape(k - 2, bsz), margin.reshape(k - 2, bsz), prm.others_decel, bounds, unsafe)
    return bounds, unsafe


# --- traffic hooks as data and L(N+1)'s profile, row by row (the compiled closed loop's: _fast_loop._period) ---


@row_function
def _wave_task(batch, sid, i, t):
    """The leader in slot ``i``'s wish from :class:`~.traffic.WaveHooks` (scenario id ``sid``; ``batch.task_wave``:
    low, span, high, low level, phase per slot)."""
    w = batch.task_wave
    level = wave_level(SCALAR, t, batch.task_period[sid], w[sid, i, 4], w[sid, i, 2], w[sid, i, 3])
    return wave_wish(SCALAR, level, w[sid, i, 0], w[sid, i, 1])


@row_function
def _wave_follower(batch, sid, t, a_x_a, a_x_d):
    """F's wish from :class:`~.traffic.WaveHooks` (``batch.f_wave``: period, phase, high, low level), clipped into
    ``[−a_x_d, a_x_a]`` as the paper's traffic clips a hook's wish."""
    w = batch.f_wave
    level = wave_level(SCALAR, t, w[sid, 0], w[sid, 1], w[sid, 2], w[sid, 3])
    return SCALAR.clip(wave_wish(SCALAR, level, -a_x_d, a_x_d + a_x_a), -a_x_d, a_x_a)


@row_function
def _sample_lanes(batch, sid, x):
    """:class:`~.traffic.WaveHooks`' sample of the lane gaps at the period's start (``x``: the row's positions) into
    its running minimum ``batch.lane_sample[sid]``."""
    low = INF
    for c in range(x.shape[0] - 1):
        low = SCALAR.minimum(low, gap_ratio(SCALAR, batch.wave_lane_valid[sid, c], x[c], x[c + 1],
                                            batch.wave_lane_margin[sid, c]))  # fmt: skip
    batch.lane_sample[sid] = SCALAR.minimum(batch.lane_sample[sid], low)


@row_function
def _profile_row(times, accels, b, t_start, dt):
    """:func:`~.traffic.profile_segment` of row ``b``: ``(a1, t_switch, a2)``."""
    now = t_start + TIME_TOL_S
    a1, t_next = accels[b, 0], INF
    for j in range(times.shape[1]):
        a1, t_next = profile_scan(SCALAR, now, times[b, j], accels[b, j], a1, t_next)
    a2 = a1
    for j in range(times.shape[1]):
        a2 = profile_after(SCALAR, t_next, times[b, j], accels[b, j], a2)
    return profile_end(SCALAR, t_start, dt, TIME_TOL_S, a1, t_next, a2)
