"""Feature map of the neural planners: :class:`Observation` → model input ``(B, F)``.

ASP-DAC'23 feeds its networks the absolute 8-vector ``[p_x, p_y, v_x, v_y, p_x_l, v_x_l, p_x_f, v_x_f]``. Absolute
longitudinal positions carry no information (the problem is invariant to a shift along the road) and make the
input distribution depend on how long a scenario has run, so the map below uses ego-relative quantities instead,
plus what connectivity adds: ``L1``'s planned speed change over the next seconds from ``obs.l1_plan``.

===============  ======  ==================================================================================
name             unit    definition
===============  ======  ==================================================================================
``p_y``          m       ego lateral centre position (original-lane centre 0, target-lane centre ``w_l``)
``v_y``          m/s     ego lateral speed, positive toward the target lane
``v_x``          m/s     ego speed (absolute: braking distances depend on it)
``gap_l``        m       ``p_x_l − p_x``: centre distance to ``L1`` (positive when ``L1`` is ahead)
``gap_f``        m       ``p_x − p_x_f``: centre distance to the follower (positive when it is behind)
``dv_l``         m/s     ``v_x_l − v_x``: positive when ``L1`` pulls away
``dv_f``         m/s     ``v_x_f − v_x``: positive when the follower closes in
``l1_dv_<k>s``   m/s     ``L1``'s planned speed change after ``k`` s, ``k`` in :data:`PLAN_TIMES_S`
                         (``dt · Σ`` of the plan); 0 = constant-speed prediction, the value a
                         non-connected ``L1`` (or a plan that ends earlier) gets
``f_connected``  –       1.0 when the follower is connected (then assumed collaborative), else 0.0
===============  ======  ==================================================================================

``L1``'s planned speed is not allowed below zero (a plan that brakes to a stop stops). Changing the names, order
or meaning of the features changes :data:`FEATURES_VERSION`; saved models record both and refuse to load against
a different feature map (:mod:`safelane.planners.nn`).
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, jitable
from .base import Observation

#: Horizons [s] at which ``L1``'s planned speed change is sampled.
PLAN_TIMES_S = (1.0, 2.0, 3.0, 4.0)

#: Model input names, in column order.
FEATURE_NAMES: tuple[str, ...] = (
    "p_y",
    "v_y",
    "v_x",
    "gap_l",
    "gap_f",
    "dv_l",
    "dv_f",
    *(f"l1_dv_{k:g}s" for k in PLAN_TIMES_S),
    "f_connected",
)

#: Bumped whenever :data:`FEATURE_NAMES` or the meaning of a column changes.
FEATURES_VERSION = 1


def plan_steps(dt: float, horizon: int, times_s=PLAN_TIMES_S) -> tuple[int, ...]:
    """How many periods of an ``H = horizon``-period plan each of ``times_s`` [s] covers (``0``: none)."""
    return tuple(min(round(t / dt), horizon) for t in times_s)


def feature_row(xp, p_x, p_y, v_x, v_y, p_x_l, v_x_l, p_x_f, v_x_f):
    """The feature map's first seven columns (:data:`FEATURE_NAMES`), for one row (``xp = SCALAR``) or a batch."""
    return p_y, v_y, v_x, p_x_l - p_x, p_x - p_x_f, v_x_l - v_x, v_x_f - v_x


def planned_change(xp, plan_sum, dt, v_x_l):
    """``L1``'s planned speed change after the periods whose accelerations add up to ``plan_sum`` [m/s²]: ``dt`` times
    the sum, floored at ``−v_x_l`` (a plan that brakes to a stop stops)."""
    return xp.maximum(dt * plan_sum, -v_x_l)


def plan_speed_change(l1_plan: np.ndarray, v_x_l: np.ndarray, dt: float, times_s=PLAN_TIMES_S) -> np.ndarray:
    """``L1``'s planned speed change [m/s] after each of ``times_s`` [s], shape ``(B, len(times_s))``.

    ``l1_plan`` ``(B, H)`` holds planned accelerations [m/s²] for the next ``H`` control periods of ``dt`` [s];
    beyond the plan ``L1`` keeps its speed. The planned speed ``v_x_l + dt·cumsum(plan)`` is floored at zero,
    so the change is at least ``−v_x_l`` (:func:`planned_change`). An empty plan (``H = 0``) gives zeros.
    """
    plan = np.asarray(l1_plan, dtype=np.float64)
    if plan.ndim != 2:
        raise ValueError(f"l1_plan must have shape (B, H), got {plan.shape}")
    batch, horizon = plan.shape
    v0 = np.asarray(v_x_l, dtype=np.float64)
    out = np.zeros((batch, len(times_s)))
    if horizon == 0:
        return out
    # The running sum up to the last period a horizon reads, column by column: the sequential sum np.cumsum makes
    # (and the compiled envs' running sum), the same bits, without summing the rest of the plan; each horizon's
    # change computed once however many of times_s share its number of periods.
    steps = plan_steps(dt, horizon, times_s)
    wanted = set(steps)
    change, running = {}, None
    for col in range(max(steps, default=0)):
        running = plan[:, 0].copy() if running is None else np.add(running, plan[:, col], out=running)
        if col + 1 in wanted:
            change[col + 1] = planned_change(ARRAY, running, dt, v0)
    for j, k in enumerate(steps):
        if k > 0:
            out[:, j] = change[k]
    return out


def features(obs: Observation, params: Params) -> np.ndarray:
    """The model input ``(B, F)`` float64 for a batch of observations, columns as in :data:`FEATURE_NAMES`.

    Every per-vehicle field of ``obs`` must have shape ``(B,)`` and ``obs.l1_plan`` shape ``(B, H)``;
    ``params.dt`` is the period of the plan.
    """
    p_x = np.asarray(obs.p_x, dtype=np.float64)
    if p_x.ndim != 1:
        raise ValueError(f"Observation fields must have shape (B,), got p_x with shape {p_x.shape}")
    cols = feature_row(ARRAY, p_x, np.asarray(obs.p_y, dtype=np.float64), np.asarray(obs.v_x, dtype=np.float64),
                       np.asarray(obs.v_y, dtype=np.float64), obs.p_x_l, obs.v_x_l, obs.p_x_f, obs.v_x_f)  # fmt: skip
    plan = plan_speed_change(obs.l1_plan, obs.v_x_l, params.dt)
    out = np.empty((p_x.shape[0], len(FEATURE_NAMES)))
    for j, col in enumerate(cols):
        out[:, j] = col
    out[:, len(cols) : len(cols) + plan.shape[1]] = plan
    out[:, -1] = np.asarray(obs.f_connected, dtype=np.float64)
    return out


jitable(feature_row, planned_change)
