"""The evasion plan: what :func:`~safelane.safety.evasion.plan_evasion` returns, evaluable at any time.

An :class:`EvasionPlan` holds, per batch element, the verdict, its :class:`Reason` bits, the switch times of the
lateral return (Eq. 5) and of the longitudinal profile (Eqs. 6–8), and the state it was planned from, so the
planned trajectory can be evaluated exactly at any ``t >= 0`` (:meth:`EvasionPlan.state`).
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..params import Params
from ._backend import ARRAY, jitable
from ._checks import finish, float_array
from .lateral import lateral_state
from .longitudinal import ego_position, ego_speed


class Reason(enum.IntFlag):
    """Per-element reason bits of an :class:`EvasionPlan` (stored as ``uint8``)."""

    OK = 0
    #: Even full braking from ``t = 0`` cannot keep ``p_m`` behind ``L1``'s worst case.
    LEADER_INFEASIBLE = 1
    #: The leader constraint is satisfiable, but the worst-case follower comes closer than ``p_m``.
    FOLLOWER_TOO_CLOSE = 2
    #: Informational: the chain ahead could not be shown collision-free, so ``L1``'s worst case is ``a_x_d``.
    CHAIN_UNSAFE = 4
    #: Informational: the ego never leaves its lane (``t_y_f = 0``); nothing to evade.
    NOTHING_TO_EVADE = 8


@dataclass(frozen=True)
class EvasionPlan:
    """A verified (or refuted) evasion trajectory for a batch of states; all arrays share the batch shape.

    Times are measured from the state the plan was computed for. Evaluate the ego's planned motion with
    :meth:`position` / :meth:`velocity`; after ``t_y_f`` the plan holds the longitudinal speed reached (the
    ego is back in its own lane, whose road ahead is free) — except where the own lane has a leader ``L0``
    (:mod:`.own_lane`): there (``continues``) the longitudinal profile goes on after ``t_y_f`` (brake, or follow),
    and where ``follows_own`` the vehicle it follows is ``L0`` (``own_*``), not ``L1``.
    """

    feasible: np.ndarray
    reason: np.ndarray
    t_y_f: np.ndarray
    t_y_switch: np.ndarray
    t_x1: np.ndarray
    t_x2: np.ndarray
    min_gap_leader: np.ndarray
    min_gap_follower: np.ndarray
    # Everything needed to evaluate the plan exactly.
    ego_px: np.ndarray
    ego_py: np.ndarray
    ego_vx: np.ndarray
    ego_vy: np.ndarray
    l1_p: np.ndarray
    l1_v: np.ndarray
    l1_decel: np.ndarray
    v_switch: np.ndarray
    t_brake_end: np.ndarray
    follows_leader: np.ndarray
    y_acc_1: np.ndarray
    y_acc_2: np.ndarray
    t_y_end: np.ndarray
    params: Params
    own_p: np.ndarray | None = None
    own_v: np.ndarray | None = None
    own_decel: np.ndarray | None = None
    follows_own: np.ndarray | None = None
    continues: np.ndarray | None = None
    min_gap_own: np.ndarray | None = None

    def __post_init__(self):  # plans without L0 carry the paper's defaults, so rows of any two plans mix
        shape = np.shape(self.feasible)
        defaults = dict(own_p=np.inf, own_v=0.0, own_decel=0.0, follows_own=False, continues=False, min_gap_own=np.inf)
        for name, value in defaults.items():
            if getattr(self, name) is None:
                dtype = bool if isinstance(value, bool) else np.float64
                object.__setattr__(self, name, np.full(shape, value, dtype=dtype))

    @property
    def lead(self):
        """``(p, v, decel)`` of the vehicle the profile follows: ``L0`` where ``follows_own``, else ``L1``."""
        if not self.follows_own.any():
            return self.l1_p, self.l1_v, self.l1_decel
        own = self.follows_own
        return (np.where(own, self.own_p, self.l1_p), np.where(own, self.own_v, self.l1_v),
                np.where(own, self.own_decel, self.l1_decel))  # fmt: skip

    def state(self, t):
        """Planned ego ``(p_x, p_y, v_x, v_y)`` at time ``t >= 0`` after the plan's state (exact).

        ``t`` broadcasts with the batch shape.
        """
        t = float_array("t", t)
        if (t < 0).any() or not np.isfinite(t).all():
            raise ValueError(f"t must be finite and >= 0; got {t!r}")
        check_broadcasts("t", t.shape, np.shape(self.t_y_f))
        with np.errstate(all="ignore"):
            return plan_state(ARRAY, self, t, *self.lead, self.params)

    def where(self, mask, other: EvasionPlan) -> EvasionPlan:
        """Element-wise choice: this plan where ``mask`` is True, ``other`` elsewhere."""
        chosen = {
            f.name: np.where(mask, getattr(self, f.name), getattr(other, f.name))
            for f in dataclasses.fields(self)
            if f.name != "params"
        }
        return EvasionPlan(**chosen, params=self.params)

    def take(self, idx) -> EvasionPlan:
        """Rows ``idx`` of a batched plan."""
        rows = {f.name: getattr(self, f.name)[idx] for f in dataclasses.fields(self) if f.name != "params"}
        return EvasionPlan(**rows, params=self.params)

    def position(self, t):
        """Planned ego ``(p_x, p_y)`` at time ``t``."""
        px, py, _, _ = self.state(t)
        return px, py

    def velocity(self, t):
        """Planned ego ``(v_x, v_y)`` at time ``t``."""
        _, _, vx, vy = self.state(t)
        return vx, vy


class PlanRecord(NamedTuple):
    """The fields of an :class:`EvasionPlan` that :func:`plan_state` reads, as a record numba can take: the compiled
    closed loop builds one from the plan it holds (``sim/_fast_held.py``); uncompiled code passes the plan itself."""

    ego_px: float
    ego_py: float
    ego_vx: float
    ego_vy: float
    t_x1: float
    v_switch: float
    t_brake_end: float
    follows_leader: bool
    t_y_f: float
    t_y_switch: float
    y_acc_1: float
    y_acc_2: float
    t_y_end: float
    continues: bool


def plan_state(xp, plan, t, lead_p, lead_v, lead_decel, prm):
    """The planned ego ``(p_x, p_y, v_x, v_y)`` at time ``t >= 0`` after the plan's state, exact: the longitudinal
    profile (Eqs. 6–8, :func:`~.longitudinal.ego_position`, :func:`~.longitudinal.ego_speed`) up to ``t_y_f``, then
    the speed reached held (the ego is back in its own lane, whose road ahead is free) — or, where the plan
    ``continues`` (a leader ``L0`` in the own lane), the profile throughout; the lateral return (Eq. 5,
    :func:`~.lateral.lateral_state`) throughout. ``plan``: an :class:`EvasionPlan` or a :class:`PlanRecord`; ``lead``:
    ``(p, v, decel)`` of the vehicle the profile follows (:attr:`EvasionPlan.lead`); ``prm``: ``Params`` or its
    ``Limits``. Backend-generic: :meth:`EvasionPlan.state` on NumPy arrays, the compiled closed loop's held plan row
    by row."""
    tt = xp.where(plan.continues, t, xp.minimum(t, plan.t_y_f))
    p, v, u, V, t2, match = plan.ego_px, plan.ego_vx, plan.t_x1, plan.v_switch, plan.t_brake_end, plan.follows_leader
    px = ego_position(xp, tt, p, v, u, V, t2, match, lead_p, lead_v, lead_decel, prm)
    vx = ego_speed(xp, tt, v, u, V, t2, match, lead_v, lead_decel, prm)
    px = px + vx * xp.maximum(t - tt, 0.0)
    py, vy = lateral_state(xp, t, plan.ego_py, plan.ego_vy, plan.t_y_switch, plan.y_acc_1, plan.y_acc_2, plan.t_y_end)
    return px, py, vx, vy


def check_broadcasts(name: str, shape, batch_shape) -> tuple[int, ...]:
    try:
        return np.broadcast_shapes(shape, batch_shape)
    except ValueError as exc:
        raise ValueError(f"{name} of shape {shape} does not broadcast with the batch shape {batch_shape}") from exc


def plan_from_core(xp, shape, args, exists, parts, lead_margin, follow_margin, params: Params, chain_unsafe=False,
                   own=None):  # fmt: skip
    """Assemble an :class:`EvasionPlan` from :func:`evasion_core`'s inputs and outputs (used by the simulator,
    which calls the unchecked core on states it built itself). ``own``: ``(l0_p, l0_v, l0_decel, margin)`` where the
    parts come from :func:`~.own_lane.own_lane_core`."""
    with np.errstate(all="ignore"):
        reason = plan_reason(xp, parts["lead_ok"], parts["follow_ok"], parts["nothing"])
    if xp is not ARRAY:
        args = tuple(np.float64(x) if not isinstance(x, bool) else np.bool_(x) for x in args)
    reason = np.asarray(finish(xp, shape, reason, np.uint8))
    reason = reason | np.where(np.asarray(chain_unsafe, dtype=bool), np.uint8(Reason.CHAIN_UNSAFE), np.uint8(0))
    f = lambda v, dt=np.float64: finish(xp, shape, v, dt)  # noqa: E731
    ego_px, ego_py, ego_vx, ego_vy, l1_p, l1_v, l1_decel = (f(x) for x in args[:7])
    return EvasionPlan(
        feasible=f(exists, np.bool_),
        reason=reason.astype(np.uint8),
        t_y_f=f(parts["t_y_f"]),
        t_y_switch=f(parts["t_y_switch"]),
        t_x1=f(parts["t_x1"]),
        t_x2=f(np.minimum(parts["t_brake_end"], parts["t_y_f"])),
        min_gap_leader=f(parts["lead_gap"] + lead_margin),
        min_gap_follower=f(parts["follow_gap"] + follow_margin),
        ego_px=ego_px,
        ego_py=ego_py,
        ego_vx=ego_vx,
        ego_vy=ego_vy,
        l1_p=l1_p,
        l1_v=l1_v,
        l1_decel=l1_decel,
        v_switch=f(parts["v_switch"]),
        t_brake_end=f(parts["t_brake_end"]),
        follows_leader=f(parts["follows_leader"], np.bool_),
        y_acc_1=f(parts["y_acc_1"]),
        y_acc_2=f(parts["y_acc_2"]),
        t_y_end=f(parts["t_y_end"]),
        params=params,
        **({} if own is None else dict(
            own_p=f(own[0]), own_v=f(own[1]), own_decel=f(own[2]), follows_own=f(parts["follows_own"], np.bool_),
            continues=f(np.ones(np.shape(exists), bool), np.bool_), min_gap_own=f(parts["own_gap"] + own[3]),
        )),
    )  # fmt: skip


def plan_reason(xp, lead_ok, follow_ok, nothing):
    """The :class:`Reason` bits of a plan from the evasion's parts (without ``CHAIN_UNSAFE``, which the caller adds):
    ``LEADER_INFEASIBLE`` where the leader constraint fails, else ``FOLLOWER_TOO_CLOSE`` where the follower's does;
    ``NOTHING_TO_EVADE`` where the ego never left its lane. Backend-generic (the compiled shield period, row by row)."""
    return (
        xp.where(lead_ok, 0, _LEADER_INFEASIBLE)
        + xp.where(lead_ok, xp.where(follow_ok, 0, _FOLLOWER_TOO_CLOSE), 0)
        + xp.where(nothing, _NOTHING_TO_EVADE, 0)
    )


# The bits as plain ints (compiled code reads them as constants).
_LEADER_INFEASIBLE, _FOLLOWER_TOO_CLOSE, _NOTHING_TO_EVADE = (
    int(Reason.LEADER_INFEASIBLE), int(Reason.FOLLOWER_TOO_CLOSE), int(Reason.NOTHING_TO_EVADE)
)


def set_rows(plan: EvasionPlan, pieces) -> EvasionPlan:
    """``plan`` with the rows of each ``(rows, sub_plan)`` piece replaced by ``sub_plan`` (same order); each field
    is copied once."""
    pieces = [(rows, sub) for rows, sub in pieces if rows.size]
    if not pieces:
        return plan
    out = {}
    for f in dataclasses.fields(plan):
        if f.name == "params":
            continue
        arr = getattr(plan, f.name).copy()
        for rows, sub in pieces:
            arr[rows] = getattr(sub, f.name)
        out[f.name] = arr
    return EvasionPlan(**out, params=plan.params)


# The plan's motion, compiled into the closed loop's held plan (sim/_fast_held.py; safety/_compile.py).
jitable(plan_state, plan_reason)
