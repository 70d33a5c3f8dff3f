"""Optional compiled kernel of the shield's candidate check (:func:`~.decide.check_candidate`; numba, extra ``fast``).

No formula lives here. :func:`candidate_kernel` is a loop over the rows without an own-lane leader that calls the
candidate check itself, :func:`~.decide.candidate_row` (the period at the candidate with L1 and F at their worst case,
the conflict zone, both worst-case gaps over the period, completion, and the evasion check with its whole plan from
the predicted state), compiled on the float backend ``SCALAR``; :func:`_candidate` is that row as the compiled closed
loop calls it (``sim/_fast_loop.py``). The completion rule and the plans are :func:`~.decide.verdict_of`'s, in NumPy,
on the kernel's output: any registered rule works. The uncompiled path evaluates the same function on NumPy arrays,
so the verdicts and plans are its bits (``tests/test_fast_decide.py``).
"""

from __future__ import annotations

import numpy as np
from numba import types

from ..params import Params
from ..safety import _compile
from ..safety._backend import FEASIBILITY_TOL_M, SCALAR, Limits
from ..safety._fast import BOOL_PARTS, FLOAT_PARTS
from ..safety._fast_base import _B, _F, announce_compiles, kernel, row_function
from ..safety.lateral import LATERAL_TOL_M
from .decide import Verdict, candidate_row, completion_level, verdict_of

_compile.register_rows()
announce_compiles()

#: The rows of :func:`candidate_kernel`'s ``floats``: the predicted states, then the plan's float parts.
STATES = ("ex", "ey", "evx", "evy", "lx", "lv", "fx", "fv")
_SIGNATURE = types.void(
    *(_F,) * 11, _B, *(types.float64,) * 9, types.Array(types.float64, 2, "C"), types.Array(types.bool_, 2, "C")
)


@row_function
def _candidate(x, y, vx, vy, ax, ay, x1, v1, d1, xf, vf, aggr, a_a, a_d, a_ym, y_safe, p_m, dt, level, lat_tol, tol):
    """One row of :func:`~.decide.candidate_row`: ``(state, period_ok, completing, parts, bits)`` — the predicted
    states (:data:`STATES`), the period's verdict, whether the step completes, and the plan from the predicted state
    (``_fast.FLOAT_PARTS``, ``_fast.BOOL_PARTS``)."""
    state, period_ok, completing, r = candidate_row(
        SCALAR, x, y, vx, vy, ax, ay, x1, v1, d1, xf, vf, aggr, Limits(a_a, a_d, a_ym, y_safe), p_m, dt, level,
        lat_tol, tol,
    )  # fmt: skip
    parts = (r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10])
    return state, period_ok, completing, parts, (r[0], r[11], r[12], r[13], r[14])


@kernel(_SIGNATURE)
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


def _rows(a: np.ndarray, n: int) -> np.ndarray:
    """``a`` as ``n`` rows (a view; no call into NumPy's broadcasting where it has them already: per-call cost at
    small batches)."""
    return a if a.shape == (n,) else np.broadcast_to(a, (n,))


def check_candidate(ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel, f_x, f_v, f_aggressive,
                    prm: Params, completion) -> Verdict:  # fmt: skip
    """:func:`~.decide.check_candidate` without an own-lane leader, through :func:`candidate_kernel`."""
    args = [np.asarray(a, dtype=np.float64) for a in (ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, l1_x, l1_v, l1_decel,
                                                      f_x, f_v)]  # fmt: skip
    n = max(a.size for a in args)
    args = [_rows(a, n) for a in args] + [_rows(np.asarray(f_aggressive, np.bool_), n)]
    floats = np.empty((len(STATES) + len(FLOAT_PARTS), n))
    flags = np.empty((2 + len(BOOL_PARTS), n), dtype=np.bool_)
    candidate_kernel(*args, prm.a_x_a, prm.a_x_d, prm.a_y_m, prm.y_safe, prm.p_m, prm.dt,
                     completion_level(completion, prm), LATERAL_TOL_M, FEASIBILITY_TOL_M, floats, flags)  # fmt: skip
    parts = {name: floats[len(STATES) + j] for j, name in enumerate(FLOAT_PARTS)}
    parts.update((name, flags[2 + j]) for j, name in enumerate(BOOL_PARTS) if j > 0)
    return verdict_of(tuple(floats[: len(STATES)]), flags[0], flags[1], flags[2], parts, args[8], args[11], prm,
                      completion)  # fmt: skip
