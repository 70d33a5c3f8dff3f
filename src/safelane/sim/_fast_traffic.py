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
from ..safety._fast_base import _max, _min
from ..safety._fast_responsible import _min_follow_decel, _responsible_bound, _responsible_ok
from ..safety.responsible import ROOT_EPS_MPS2

_M = types.Array(types.float64, 2, "A", readonly=True)
_MB = types.Array(types.bool_, 2, "A", readonly=True)
_V = types.Array(types.float64, 1, "A", readonly=True)
_SIGNATURE = types.void(
    _M, _M, _M, _MB, _MB, _M, _M, _V, _V, types.boolean, _MB, _M, *(types.float64,) * 5,
    types.Array(types.float64, 2, "F"),
)  # fmt: skip


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
            slack = x[b, i + 1] - x[b, i] - margin[b, i]
            v_f = v[b, i]
            v_l = v[b, i + 1]
            d = bounds[b, i + 1]
            own = bounds[b, i]
            want = _min(task[b, i], _responsible_bound(slack, v_f, v_l, d, own, dt) - eps)
            ok = True
            if own < d:  # the closed form is exact where the own bound is at least the one ahead: else confirm it
                ok = _responsible_ok(want, slack, v_f, v_l, d, own, dt, tol, half, tol)
            a_conn = _max(want if ok else -own, -own)
            if any_violation and violating[b, i]:
                z = _min(_min_follow_decel(slack, v_f, v_l, d, half, tol), a_x_d)
                lo = _min(z, decel_last[b])
                hi = _max(z, decel_last[b])
                a_conn = -(lo + pick[b, i] * (hi - lo))
            acc[b, i] = a_conn
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
        np.asarray(violate_pick, dtype=np.float64), prm.a_x_d, prm.dt, ROOT_EPS_MPS2, FEASIBILITY_TOL_M,
        0.5 * FEASIBILITY_TOL_M, acc,
    )  # fmt: skip
    return acc
