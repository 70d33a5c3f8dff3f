"""Optional compiled kernel of the connected leaders' rule (:func:`~.behaviours.leader_accels`; numba, extra ``fast``).

:func:`leader_kernel` is ``leader_accels`` element by element: each connected ``L_i`` keeps its task while that
keeps it responsible behind the vehicle ahead's chain bound with its own bound as its braking
(:func:`~safelane.safety.responsible.responsible_bound`, confirmed by
:func:`~safelane.safety.responsible.responsible_ok` where its bound is softer than the one ahead), else brakes at
its bound; an unexpected violation brakes at ``U[z_i, a_x_N+1_d]``; ``L(N+1)`` follows its profile. The NumPy
function evaluates ~50 array operations over every slot and a masked exact check; the kernel does the same
arithmetic per element, only where a leader acts, in the NumPy path's evaluation order (the scalar helpers of
:mod:`safelane.safety._fast_responsible`), so the accelerations are the same bits
(``tests/test_fast_traffic.py``). The NumPy function stays the reference and the fallback.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types

from ..params import Params
from ..safety._backend import FEASIBILITY_TOL_M
from ..safety._fast_base import (
    _max,
    _min,
    announce_compile,
    row_function,
)
from ..safety._fast_responsible import _min_follow_decel, _responsible_bound, _responsible_ok
from ..safety.responsible import ROOT_EPS_MPS2

announce_compile(__file__)

_M = types.Array(types.float64, 2, "A", readonly=True)
_MB = types.Array(types.bool_, 2, "A", readonly=True)
_V = types.Array(types.float64, 1, "A", readonly=True)
_SIGNATURE = types.void(
    _M, _M, _M, _MB, _MB, _M, _M, _V, _V, types.boolean, _MB, _M, *(types.float64,) * 5,
    types.Array(types.float64, 2, "F"),
)  # fmt: skip


@row_function
def _leader_accel(slack, v_f, v_l, d, own, task, violating, pick, decel_last, a_x_d, dt, eps, tol, half):
    """One connected leader's acceleration (:func:`leader_kernel`'s element): ``slack`` to the vehicle ahead, its
    bound ``d`` and the leader's own bound ``own``."""
    want = _min(task, _responsible_bound(slack, v_f, v_l, d, own, dt) - eps)
    # The closed form is exact where the own bound is at least the one ahead: else confirm it — unless the answer is
    # -own either way (want < -own: the maximum below is -own whatever the check says).
    ok = True
    if own < d and not want < -own:
        ok = _responsible_ok(want, slack, v_f, v_l, d, own, dt, tol, half, tol)
    a_conn = _max(want if ok else -own, -own)
    if violating:
        z = _min(_min_follow_decel(slack, v_f, v_l, d, half, tol), a_x_d)
        lo = _min(z, decel_last)
        hi = _max(z, decel_last)
        a_conn = -(lo + pick * (hi - lo))
    return a_conn


@numba.njit(_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def leader_kernel(
    x, v, margin, is_last, acts, bounds, task, a_last, decel_last, any_violation, violating, pick, a_x_d, dt, eps,
    tol, half, acc,
):  # fmt: skip
    """Write :func:`~.behaviours.leader_accels`' accelerations into ``acc`` (``(B, K)``, zero on entry). Inputs as
    that function's; ``violating``/``pick`` are read only where ``any_violation``."""
    bsz, k = x.shape
    for i in range(1, k - 1):  # followers are slots 1..K-2, each behind the next slot (column by column: F order)
        for b in range(bsz):
            if not acts[b, i]:
                continue
            breaks = any_violation and violating[b, i]
            acc[b, i] = _leader_accel(
                x[b, i + 1] - x[b, i] - margin[b, i], v[b, i], v[b, i + 1], bounds[b, i + 1], bounds[b, i],
                task[b, i], breaks, pick[b, i] if breaks else 0.0, decel_last[b], a_x_d, dt, eps, tol, half,
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
    leader_kernel(
        *args, any_violation, np.asarray(violating, dtype=np.bool_),
        np.asarray(violate_pick, dtype=np.float64), prm.others_decel, prm.dt, ROOT_EPS_MPS2, FEASIBILITY_TOL_M,
        0.5 * FEASIBILITY_TOL_M, acc,
    )  # fmt: skip
    return acc


_R = types.Array(types.float64, 1, "A", readonly=True)
_RB = types.Array(types.bool_, 1, "A", readonly=True)
_FOLLOWER_SIGNATURE = types.void(
    *(_R,) * 6, _RB, _RB, _R, types.boolean, _R, types.boolean, *(types.float64,) * 7,
    types.Array(types.float64, 1, "C"),
)  # fmt: skip


@numba.njit(error_model="numpy", nogil=True)
def _responsible_accel(a_wanted, slack, v_f, v_l, lead_decel, a_x_d, dt, eps):  # responsible.responsible_accel
    bound = _responsible_bound(slack, v_f, v_l, lead_decel, a_x_d, dt)
    return a_wanted if bound > a_wanted else _max(bound - eps, -a_x_d)


@row_function
def _follower_accel(fx, fv, lx, lv, ex, evx, aggr, completed, gap0, has_wanted, wanted, ignores_ego, p_m, a_x_a,
                    a_x_d, open_decel, open_gap_m, dt, eps):  # fmt: skip
    """F's acceleration (:func:`follower_kernel`'s element)."""
    gap_ego = ex - fx
    gap_l1 = lx - fx
    if has_wanted:
        want = wanted
    elif aggr:
        want = _min(_max(0.5 * (gap_l1 - p_m - 1.0) + 1.5 * (lv - fv), -a_x_d), a_x_a)
    elif gap_ego < gap0 + open_gap_m:
        want = -open_decel
    else:
        want = _min(_max(evx - fv, -open_decel), open_decel)
    a = _responsible_accel(want, gap_l1 - p_m, fv, lv, a_x_d, a_x_d, dt, eps)
    if gap_ego > 0.0 and ((not aggr) or completed) and not ignores_ego:
        a = _responsible_accel(a, gap_ego - p_m, fv, evx, a_x_d, a_x_d, dt, eps)
    return a


@numba.njit(_FOLLOWER_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def follower_kernel(
    f_x, f_v, l1_x, l1_v, ego_x, ego_vx, aggressive, completed, gap0, has_wanted, wanted, ignores_ego, p_m, a_x_a,
    a_x_d, open_decel, open_gap_m, dt, eps, out,
):  # fmt: skip
    """:func:`~.behaviours.follower_accel` per scenario into ``out``; ``wanted`` is read only where ``has_wanted``."""
    for i in range(out.shape[0]):
        out[i] = _follower_accel(
            f_x[i], f_v[i], l1_x[i], l1_v[i], ego_x[i], ego_vx[i], aggressive[i], completed[i], gap0[i], has_wanted,
            wanted[i], ignores_ego, p_m, a_x_a, a_x_d, open_decel, open_gap_m, dt, eps,
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
        float(open_decel), float(open_gap_m), prm.dt, ROOT_EPS_MPS2, out,
    )  # fmt: skip
    return out


_CHAIN_SIGNATURE = types.void(
    _M, _M, _M, _M, *(types.float64,) * 3, types.Array(types.float64, 2, "F"), types.Array(types.bool_, 1, "C")
)


@row_function
def _chain_row(x, v, r, promise, margin, col, a_x_d, half, tol, bounds):
    """One scenario of :func:`chain_kernel`: row ``r`` of ``x``, ``v`` and ``bounds`` (``(., K)``), column ``col`` of
    ``promise``, ``margin`` (``(N, .)``); writes ``bounds[r]``, returns ``unsafe``."""
    k = x.shape[1]
    a_ahead = a_x_d
    broken = False
    bounds[r, 0] = a_x_d
    bounds[r, k - 1] = a_x_d
    for i in range(k - 3, -1, -1):  # link i: L(i+1) behind L(i+2), slots i+1 and i+2
        slack = x[r, i + 2] - x[r, i + 1] - margin[i, col]
        z = _min_follow_decel(slack, v[r, i + 1], v[r, i + 2], a_ahead, half, tol)
        broken = broken | (z > a_x_d)
        a_ahead = _min(_max(promise[i, col], z), a_x_d)
        bounds[r, i + 1] = a_ahead
    return broken


@numba.njit(_CHAIN_SIGNATURE, cache=True, nogil=True, error_model="numpy")
def chain_kernel(x, v, promise, margin, a_x_d, half, tol, bounds, unsafe):
    """:meth:`~.step.ClosedLoop.chain` per scenario: the scan of :func:`safelane.safety.chain.propagate_chain` from
    ``L(N+1)`` (``a_x_d``) down to ``L1`` into ``bounds`` (``(B, K)``, F's slot ``a_x_d``) and ``unsafe``.
    ``promise``, ``margin``: ``(N, B)`` rows of the links ``L1..LN``."""
    for b in range(x.shape[0]):
        unsafe[b] = _chain_row(x, v, b, promise, margin, b, a_x_d, half, tol, bounds)


def chain_bounds(x, v, promise, margin, prm: Params):
    """:func:`chain_kernel`: ``(bounds (B, K), unsafe (B,))``."""
    bsz, k = x.shape
    bounds = np.empty((bsz, k), order="F")
    unsafe = np.empty(bsz, dtype=np.bool_)
    chain_kernel(x, v, promise.reshape(k - 2, bsz), margin.reshape(k - 2, bsz), prm.others_decel,
                 0.5 * FEASIBILITY_TOL_M, FEASIBILITY_TOL_M, bounds, unsafe)  # fmt: skip
    return bounds, unsafe
