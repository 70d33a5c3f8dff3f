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

import dataclasses
import enum
import math
from dataclasses import dataclass

import numpy as np

from ..params import Params
from ._backend import ARRAY
from ._checks import bool_array, check_params, finish, float_array, prepare
from .chain import braked_position
from .lateral import lateral_core, lateral_state
from .longitudinal import FEASIBILITY_TOL_M, ego_position, ego_speed, longitudinal_core


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


@dataclass(frozen=True)
class EvasionPlan:
    """A verified (or refuted) evasion trajectory for a batch of states; all arrays share the batch shape.

    Times are measured from the state the plan was computed for. Evaluate the ego's planned motion with
    :meth:`position` / :meth:`velocity`; after ``t_y_f`` the plan holds the longitudinal speed reached (the
    ego is back in its own lane, whose road ahead is free).
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

    def state(self, t):
        """Planned ego ``(p_x, p_y, v_x, v_y)`` at time ``t >= 0`` after the plan's state (exact).

        ``t`` broadcasts with the batch shape.
        """
        t = float_array("t", t)
        if (t < 0).any() or not np.isfinite(t).all():
            raise ValueError(f"t must be finite and >= 0; got {t!r}")
        T = self.t_y_f
        _check_broadcasts("t", t.shape, np.shape(T))
        lon = (self.ego_px, self.ego_vx, self.t_x1, self.v_switch, self.t_brake_end, self.follows_leader)
        p, v, u, V, t2, match = lon
        lead = (self.l1_p, self.l1_v, self.l1_decel)
        with np.errstate(all="ignore"):
            tt = np.minimum(t, T)
            px = ego_position(ARRAY, tt, p, v, u, V, t2, match, *lead, self.params)
            vx = ego_speed(ARRAY, tt, v, u, V, t2, match, self.l1_v, self.l1_decel, self.params)
            px = px + vx * np.maximum(t - T, 0.0)
            lat = (self.t_y_switch, self.y_acc_1, self.y_acc_2, self.t_y_end)
            py, vy = lateral_state(ARRAY, t, self.ego_py, self.ego_vy, *lat)
        return px, py, vx, vy

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


_PLAN_INPUTS = ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "f_p", "f_v")


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
    """Backend-generic core shared by :func:`plan_evasion` and :func:`evasion_exists`.

    Returns ``(exists, parts)`` where ``parts`` is a dict of the plan's fields.
    """
    T, t_y1, y_acc_1, y_acc_2, t_y_end = lateral_core(xp, ego_py, ego_vy, prm)
    lead_ok, u, V, t2, match, lead_gap = longitudinal_core(
        xp, ego_px, ego_vx, l1_p, l1_v, l1_decel, T, lead_margin, prm, tol
    )
    a_a, a_d = prm.a_x_a, prm.a_x_d
    l1_stop = xp.stop_time(l1_v, l1_decel)
    f_stop = xp.stop_time(f_v, a_d)
    candidates = (
        0.0 * T,
        u,
        t2,
        f_stop,
        xp.div(f_v - ego_vx, a_a + a_d, 0.0),
        xp.div(f_v - l1_v, a_d - l1_decel, 0.0),
        T,
    )
    if xp is ARRAY and bool(np.all(T == 0.0)):  # nothing to evade anywhere: every candidate clips to 0
        candidates = candidates[:1]
    if xp is ARRAY:  # every candidate in one stacked evaluation (the same arithmetic)
        c = xp.clip(np.stack(np.broadcast_arrays(*candidates)), 0.0, T)
        ego = ego_position(xp, c, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, prm, l1_stop)
        follow_gap = (ego - follower_offset(xp, c, f_p, f_v, aggressive, prm, f_stop) - follow_margin).min(0)
    else:
        follow_gap = None
        for c in candidates:
            c = xp.clip(c, 0.0, T)
            ego = ego_position(xp, c, ego_px, ego_vx, u, V, t2, match, l1_p, l1_v, l1_decel, prm, l1_stop)
            gap = ego - follower_offset(xp, c, f_p, f_v, aggressive, prm, f_stop) - follow_margin
            follow_gap = gap if follow_gap is None else xp.minimum(follow_gap, gap)
    follow_ok = follow_gap >= -tol
    nothing = T <= 0.0
    exists = nothing | (lead_ok & follow_ok)
    parts = dict(
        t_y_f=T,
        t_y_switch=t_y1,
        y_acc_1=y_acc_1,
        y_acc_2=y_acc_2,
        t_y_end=t_y_end,
        lead_ok=lead_ok,
        follow_ok=follow_ok,
        nothing=nothing,
        t_x1=u,
        v_switch=V,
        t_brake_end=t2,
        follows_leader=match,
        lead_gap=lead_gap,
        follow_gap=follow_gap,
    )
    return exists, parts


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
        upper={"l1_decel": params.a_x_d},
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
        l1_p, l1_v, l1_decel: ``L1``'s position, speed and worst-case deceleration (``[0, a_x_d]``, e.g. from
            :func:`worst_case_leader_decel`).
        f_p, f_v: follower position and speed.
        follower_aggressive: bool; the follower's assumed worst case (Eq. 9).
        leader_human, follower_human: keep ``p_m_human`` instead of ``p_m`` to that vehicle (footnote 1).

    Returns a bool array of the batch shape (a NumPy bool scalar for scalar inputs). Gaps within
    ``FEASIBILITY_TOL_M`` of the margin count as kept.
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
    if xp is ARRAY and math.prod(shape) > CHUNK:
        return _exists_chunked(args, shape, params)
    with np.errstate(all="ignore"):
        exists, _ = evasion_core(xp, *args, params)
    return finish(xp, shape, exists, np.bool_)


#: Batches larger than this many elements are checked ``CHUNK`` elements at a time. The core makes a few
#: hundred element-wise temporaries; in chunks they stay in cache, and at 64 KiB each they stay below glibc's
#: 128 KiB ``mmap`` threshold (larger blocks are mapped and unmapped, page fault by page fault, every time).
#: That makes a batch of a million about twice as fast as one pass. The arithmetic is unchanged.
CHUNK = 8192


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
    if _check_broadcasts("chain_unsafe", chain_unsafe.shape, shape) != shape:
        raise ValueError(f"chain_unsafe of shape {chain_unsafe.shape} must broadcast to the batch shape {shape}")
    with np.errstate(all="ignore"):
        exists, parts = evasion_core(xp, *args, params)
    return plan_from_core(xp, shape, args, exists, parts, lead_margin, follow_margin, params, chain_unsafe)


def _check_broadcasts(name: str, shape, batch_shape) -> tuple[int, ...]:
    try:
        return np.broadcast_shapes(shape, batch_shape)
    except ValueError as exc:
        raise ValueError(f"{name} of shape {shape} does not broadcast with the batch shape {batch_shape}") from exc


def plan_from_core(xp, shape, args, exists, parts, lead_margin, follow_margin, params: Params, chain_unsafe=False):
    """Assemble an :class:`EvasionPlan` from :func:`evasion_core`'s inputs and outputs (used by the simulator,
    which calls the unchecked core on states it built itself)."""
    with np.errstate(all="ignore"):
        reason = (
            xp.where(parts["lead_ok"], 0, int(Reason.LEADER_INFEASIBLE))
            + xp.where(parts["lead_ok"], xp.where(parts["follow_ok"], 0, int(Reason.FOLLOWER_TOO_CLOSE)), 0)
            + xp.where(parts["nothing"], int(Reason.NOTHING_TO_EVADE), 0)
        )
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
    )
