"""The envs' compiled step (numba, extra ``fast``): one control period of every row — the closed loop's own period,
``sim/_fast_loop._step_rows``, what ``step_kernel`` runs (compiled and cached once for both) — then what the agent
gets from it, in the same compiled call.

No rule lives here: the period is the closed loop's own; the observation is
:func:`~safelane.planners.features.feature_row` and :func:`~safelane.planners.features.planned_change` (the feature
map's closed forms, which :func:`~safelane.planners.features.features` evaluates on NumPy arrays); the reward, the
executed acceleration and the flags are :func:`~.core.outcome_core`. One piece mirrors NumPy code, and only its
bookkeeping: ``L1``'s shared plan — :meth:`~safelane.sim.step.ClosedLoop.observe` holds L1's last acceleration
for ``l1_plan_steps`` periods (where ``ClosedLoop.shares_plan``) and
:func:`~safelane.planners.features.plan_speed_change` sums it with ``np.cumsum`` — is summed here period by period
in the same order, because a compiled row cannot call NumPy's cumsum on a ``(B, H)`` plan it never builds. The
horizons come from :func:`~safelane.planners.features.plan_steps`, the rows from ``shares_plan``, so only the running
sum is written twice. ``tests/test_env_compiled.py`` compares every output with the NumPy env's, bit for bit.

In the realistic world (own lane, sensing error, actuation delay) the agent gets what the NumPy env gives it from
:class:`~safelane.sim.step.SimState`: the world's flags — ``collided`` and ``violated`` count the ego's collisions
and ``p_m`` violations against the own lane's leader ``L0`` (``ClosedLoop._own_lane``; ``rb``'s columns 0 and 1
include ``l0_collided``, ``l0_violated``), and the completion is the world's (``rb[:, 7]``, ``SimState.completed``:
under an actuation delay the command acting completes the lane change, not the one the shield issues, whose flag
the shield keeps apart) — and the observation of the true states (``ClosedLoop.observe`` reads the state, never the
measured situation; the feature map has no ``L0`` column). ``tests/test_env_realworld.py`` compares them.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types
from numba.extending import overload

from ..planners import features as _features  # noqa: F401  (its closed forms are marked: registered below)
from ..planners.features import feature_row, planned_change
from ..safety import _compile
from ..safety._backend import SCALAR
from ..safety._fast_base import announce_compiles
from ..shield.decide import ABORT, HESITATE
from ..sim._fast_loop import LoopBatch, _step_rows
from ..sim._fast_rows import Rows, Sense, _scratch
from . import core as _core  # noqa: F401  (outcome_core is marked: registered below)
from .core import outcome_core

_compile.register_rows()
announce_compiles()

#: The env's scalars (:func:`env_step_kernel`'s ``env``): the period, the lane boundary, the horizon in periods and
#: :class:`~.core.RewardConfig`'s weights in :meth:`~.core.RewardConfig.weights`' order.
ENV = ("dt", "y_boundary", "max_steps", "progress", "success", "collision", "comfort", "time", "cost", "intervention")
#: :func:`env_step_kernel`'s per-row outcome columns (:func:`~.core.outcome_core`'s results, flags as 0.0/1.0).
OUTCOME = ("reward", "a_x", "a_y", "crashed", "cost", "success", "terminated", "truncated")


@numba.njit(cache=True, nogil=True, error_model="numpy")
def env_step_kernel(prm, period_prm, batch, rows, proposal, env, view, steps, obs, outcome, behaviour, finite, sense):
    """One period of every row of ``rows`` (``_fast_rows.Rows``'s arrays as a plain tuple, in place; ``batch``:
    ``_fast_loop.LoopBatch``'s as a plain tuple) with the agents' proposals ``(B, 2)``,
    then each row's observation into ``obs`` ``(B, F)`` and its :data:`OUTCOME` into ``outcome``; ``env``:
    :data:`ENV`'s values; ``view``: ``(shares_plan (B,), f_connected (B,), plan_steps (len(PLAN_TIMES_S),),
    plan_sums (l1_plan_steps,))`` — the rows whose ``L1`` shares its plan, the follower's flag, how many of the plan's
    periods each feature's horizon covers, and a scratch array; ``steps``: each row's periods so far, this one
    included; ``sense``: the scratch of the shield's sensing box (``_fast_rows.Sense``'s arrays as a plain tuple,
    ``_fused.sense_scratch``), ``None`` where it is off (compiled without it, as ``step_kernel``). Plain tuples, not
    the named ones: numba types a call's plain tuples of arrays in C, named ones in Python (measured: 13 µs of a
    single env's step of about 100 µs); the names are put back here, for free."""
    batch, rows = LoopBatch(*batch), Rows(*rows)
    before = np.empty((rows.x.shape[0], 6))
    _env_rows(prm, batch, rows, proposal, env, view, steps, obs, outcome, behaviour, finite,
              _scratch(rows, period_prm, _named_sense(sense)), before)  # fmt: skip


def _named_sense(sense):
    """``sense`` as ``_fast_rows.Sense`` (a plain tuple of its arrays), ``None`` as it is."""
    raise NotImplementedError("compiled only (numba)")


@overload(_named_sense, inline="always", jit_options=dict(error_model="numpy", nogil=True))
def _named_sense_typed(sense):
    if isinstance(sense, types.NoneType):
        return lambda sense: None
    return lambda sense: Sense(*sense)


@numba.njit(nogil=True, error_model="numpy", _nrt=False)
def _env_rows(prm, batch, rows, proposal, env, view, steps, obs, outcome, behaviour, finite, w, before):
    """The closed loop's period of every row (``_fast_loop._step_rows``, compiled once for ``step_kernel`` and the
    envs), then each row's observation and outcome from its state before (``before``, kept here first) and after."""
    dt, y_boundary, max_steps = env[0], env[1], env[2]
    w_pro, w_suc, w_col, w_com, w_tim, w_cos, w_int = env[3], env[4], env[5], env[6], env[7], env[8], env[9]
    shares_plan, f_connected, plan_steps, sums = view
    rf, rb, x, v, acc = rows.rf, rows.rb, rows.x, rows.v, rows.acc
    for b in range(rows.x.shape[0]):
        before[b, 0], before[b, 1], before[b, 2] = rf[b, 2], rf[b, 1], rf[b, 3]
        before[b, 3] = 1.0 if rb[b, 0] else 0.0
        before[b, 4] = 1.0 if rb[b, 1] else 0.0
        before[b, 5] = 1.0 if rb[b, 7] else 0.0
    _step_rows(prm, batch, rows, proposal, behaviour, finite, w)
    for b in range(rows.x.shape[0]):
        code = behaviour[b]
        ex, ey, evx, evy = rf[b, 0], rf[b, 1], rf[b, 2], rf[b, 3]
        # --- the observation (ClosedLoop.observe, then features) ---
        cols = feature_row(SCALAR, ex, ey, evx, evy, x[b, 1], v[b, 1], x[b, 0], v[b, 0])
        for j in range(7):
            obs[b, j] = cols[j]
        a_plan = acc[b, 1] if shares_plan[b] else 0.0
        running = 0.0
        for h in range(sums.shape[0]):
            running = running + a_plan
            sums[h] = running
        for j in range(plan_steps.shape[0]):
            n = plan_steps[j]
            obs[b, 7 + j] = planned_change(SCALAR, sums[n - 1], dt, v[b, 1]) if n > 0 else 0.0
        obs[b, 7 + plan_steps.shape[0]] = 1.0 if f_connected[b] else 0.0
        # --- what the agent gets (outcome_core) ---
        intervened = 1.0 if (code == HESITATE or code == ABORT) else 0.0
        at_horizon = 1.0 if steps[b] >= max_steps else 0.0
        c1, v1, d1 = 1.0 if rb[b, 0] else 0.0, 1.0 if rb[b, 1] else 0.0, 1.0 if rb[b, 7] else 0.0
        out = outcome_core(SCALAR, dt, y_boundary, w_pro, w_suc, w_col, w_com, w_tim, w_cos, w_int, before[b, 0],
                           before[b, 1], before[b, 2], before[b, 3], before[b, 4], before[b, 5], evx, ey, evy, c1, v1,
                           d1, at_horizon, intervened)  # fmt: skip
        for j in range(8):
            outcome[b, j] = out[j]
