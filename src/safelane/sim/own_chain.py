"""The ego's own lane as a chain (docs/real_roads.md, "A connected own lane"): ``L0`` and the vehicles ahead of it,
the first ``own_n_connected`` of them connected (V2X: state and a promised maximum deceleration), then one that is
not, the *head*, which drives the own lane's profile (``ScenarioBatch.l0_profile_*``). With no connected vehicle
the head is ``L0`` itself: the world before the chain, bit for bit.

The connected ones drive as the target lane's connected leaders do under the ``worst_case`` rule — the same
functions (:func:`~.behaviours.lane_bounds`, :func:`~.behaviours.leader_accels`), on the own lane laid out as the
target lane (an empty slot 0 where the target lane has ``F``): their own task — hold their initial speed, then,
from an instant of their own (``own_brake_t``), brake at their full promise — capped by what keeps them responsible
behind the vehicle ahead's worst case from the chain analysis on the true states, never beyond their own bound (its
running minimum). That is the worst case the shield's own-lane analysis assumes (Eqs. 1–3 on the own lane): they
brake as hard and as early as their promise lets them, and beyond it only as far as the vehicle ahead forces.

**One source.** A connected one's task is :func:`own_task` (over :func:`~.behaviours.hold_speed` and
:func:`~.behaviours.task_core`), backend-generic like the rules it calls; :meth:`OwnLane.period` evaluates the lane on
arrays (``ARRAY``), and the compiled closed loop (``sim/_fast_world.own_lane_motion``) calls the same closed forms row
by row (the chain scan ``_fast_traffic._chain_row``, the leaders' rule ``_fast_traffic._leader_row``, the motion
:func:`~.kinematics.constant_segment` and ``_fast_world._switched``): the same bits
(``tests/test_fast_own_chain_loop.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, jitable
from ..tolerances import TIME_TOL_S
from .behaviours import hold_speed, lane_bounds, leader_accels, leader_roles, task_core
from .checks import lane_checks
from .kinematics import Fleet
from .traffic import profile_segment

#: Where the scan puts an empty slot: this far ahead of the head, at rest (it constrains nobody).
_EMPTY_AHEAD_M = 1.0e6


@dataclass(frozen=True)
class OwnLane:
    """A batch's own lane, constant over a run: ``K`` slots, ``L0`` first."""

    n_connected: np.ndarray  # (B,)
    promise: np.ndarray  # (B, K-1) promised maximum deceleration of the connected ones (L0 first)
    brake_t: np.ndarray  # (B, K-1) when each connected one starts braking at its promise
    v_desired: np.ndarray  # (B, K) initial speeds (the connected ones hold them until they brake)
    head: np.ndarray  # (B, K) the non-connected vehicle driving the profile

    @classmethod
    def of(cls, batch, prm: Params) -> OwnLane:
        check_chain(batch, prm)
        n = len(batch)
        k = 1 if batch.own_ahead_x is None else 1 + batch.own_ahead_x.shape[1]
        nc = np.zeros(n, np.int64) if batch.own_n_connected is None else batch.own_n_connected.astype(np.int64)
        promise = np.zeros((n, k - 1)) if batch.own_promise is None else np.asarray(batch.own_promise, float)
        brake = np.full((n, k - 1), np.inf) if batch.own_brake_t is None else np.asarray(batch.own_brake_t, float)
        v = start(batch)[1]
        head = np.arange(k)[None, :] == nc[:, None]
        return cls(n_connected=nc, promise=promise, brake_t=brake, v_desired=v.copy(), head=head)

    @property
    def slots(self) -> int:
        return self.v_desired.shape[1]

    def situation_fields(self, x, v) -> dict:
        """The own lane as the shield's :class:`~safelane.shield.Situation` takes it."""
        return dict(own_x=x, own_v=v, own_promise=self.promise, own_n_connected=self.n_connected)

    def period(self, batch, t: float, x, v, cap, prm: Params):
        """The own lane over the period ``[t, t + dt]``: ``(fleet, cap)`` — every slot's exact motion (an empty
        slot at 0, at rest) and the running minimum of the chain bounds."""
        present = np.isfinite(x)
        a1, t_sw, a2 = profile_segment(t, prm.dt, batch.l0_profile_t, batch.l0_profile_a)  # the head's
        if self.slots == 1:
            acc = a1[:, None]
        else:
            acc, cap = self._connected(t, x, v, present, cap, a1, prm)
        on = self.head & (t_sw < prm.dt)[:, None]
        x0 = np.where(present, x, 0.0)
        fleet = Fleet.switched(x0, v, acc, np.where(on, t_sw[:, None], prm.dt), np.where(on, a2[:, None], acc),
                               prm.dt)  # fmt: skip
        return fleet, cap

    def _connected(self, t, x, v, present, cap, a_head, prm: Params):
        """The accelerations of every slot (the head's ``a_head``) and the new running minimum of the bounds."""
        n, k = x.shape
        head_x = x[np.arange(n), np.minimum(self.n_connected, k - 1)]
        far = head_x[:, None] + _EMPTY_AHEAD_M * np.arange(1, k + 1)[None, :]
        xs = np.where(present, x, far)
        vs = np.where(present, v, 0.0)
        in_chain = np.arange(k - 1)[None, :] < self.n_connected[:, None]
        promise_vm = np.where(in_chain, self.promise, prm.others_decel).T.copy()
        margin_vm = np.full((k - 1, n), prm.p_m)
        lane = lambda a, slot0: np.asfortranarray(np.column_stack([np.full(n, slot0), a]))  # noqa: E731
        lx, lv = lane(xs, 0.0), lane(vs, 0.0)
        bounds, _ = lane_bounds(lx, lv, promise_vm, margin_vm, prm)
        cap = np.minimum(cap, bounds[:, 1:])
        task = own_task(ARRAY, t, self.brake_t, v[:, :-1], self.v_desired[:, :-1], self.promise, prm.a_x_a)
        valid = np.column_stack([np.zeros(n, bool), present])
        connected = np.column_stack([np.zeros(n, bool), in_chain, np.zeros(n, bool)])
        roles = leader_roles(valid, connected, self.n_connected)
        acc = leader_accels(lx, lv, np.full((n, k + 1), prm.p_m, order="F"), roles,
                            lane(cap, prm.others_decel), lane(np.column_stack([task, np.zeros(n)]), 0.0), a_head,
                            np.full(n, prm.others_decel), None, None, prm)  # fmt: skip
        return np.asfortranarray(acc[:, 1:]), cap

    def pair_collisions(self, fleet: Fleet, present, prm: Params):
        """``(collided, violated)`` ``(B,)``: consecutive own-lane vehicles ran into each other or inside ``p_m``
        (exact, :func:`~.checks.lane_checks`; the traffic's own soundness, never the ego's)."""
        valid = present[:, 1:] & present[:, :-1]
        collided, violated, _ = lane_checks(None, prm, fleet, (valid, np.full(valid.shape, prm.p_m)))
        return collided, violated


def own_task(xp, t, brake_t, v, v_desired, promise, a_x_a):
    """A connected own-lane vehicle's task at ``t``: hold its initial speed ``v_desired`` (:func:`~.behaviours.
    hold_speed`) until its own instant ``brake_t`` (one that falls within ``TIME_TOL_S`` after ``t`` counts: round-off
    in the period count), then brake at its full ``promise``; inside ``[−promise, a_x_a]``
    (:func:`~.behaviours.task_core`). Backend-generic."""
    wanted = xp.where(t + TIME_TOL_S >= brake_t, -promise, hold_speed(xp, v, v_desired))
    return task_core(xp, wanted, promise, a_x_a)


_FIELDS = ("own_ahead_x", "own_ahead_v", "own_promise", "own_n_connected", "own_brake_t")


def check_chain(batch, prm: Params) -> None:
    """The own-lane chain's fields, or a ``ValueError`` naming the field, the value and the range."""
    given = [getattr(batch, f) is not None for f in _FIELDS]
    if not any(given):
        return
    if not all(given):
        raise ValueError(f"ScenarioBatch.{', '.join(_FIELDS)} go together (all or none)")
    n = len(batch)
    x, v = (np.asarray(getattr(batch, f), float) for f in _FIELDS[:2])
    if x.ndim != 2 or x.shape[0] != n or x.shape[1] < 1:
        raise ValueError(f"ScenarioBatch.own_ahead_x must have shape ({n}, J >= 1); got {x.shape}")
    for name in _FIELDS[1:3] + _FIELDS[4:]:
        if np.shape(getattr(batch, name)) != x.shape:
            raise ValueError(f"ScenarioBatch.{name} must have shape {x.shape}; got {np.shape(getattr(batch, name))}")
    nc, promise, brake = np.asarray(batch.own_n_connected), np.asarray(batch.own_promise, float), batch.own_brake_t
    if nc.shape != (n,) or (nc < 0).any() or (nc > x.shape[1]).any():
        raise ValueError(f"ScenarioBatch.own_n_connected must be ({n},) in [0, J={x.shape[1]}]; got {nc!r}")
    if not ((promise >= 0.0) & (promise <= prm.a_x_d)).all():
        bad = float(promise[~((promise >= 0.0) & (promise <= prm.a_x_d))].flat[0])
        raise ValueError(f"ScenarioBatch.own_promise must lie in [0, a_x_d={prm.a_x_d}]; got {bad!r}")
    if not (np.asarray(brake, float) >= 0.0).all():
        raise ValueError("ScenarioBatch.own_brake_t must be >= 0 (inf: never)")
    if not (np.isfinite(v).all() and (v >= 0.0).all()) or (x == -np.inf).any() or np.isnan(x).any():
        raise ValueError("ScenarioBatch.own_ahead_x must be finite or +inf (none), own_ahead_v finite and >= 0")
    slot = np.arange(1, x.shape[1] + 1)[None, :]
    present = np.isfinite(x)
    if (present != (slot <= nc[:, None])).any() or (present[:, 0] & ~np.isfinite(batch.l0_x)).any():
        raise ValueError("ScenarioBatch.own_ahead_x: exactly the own_n_connected vehicles ahead of L0 (the last one "
                         "the head) must be present, and only where L0 is")  # fmt: skip
    behind = np.column_stack([batch.l0_x, x[:, :-1]])
    if (present & ~(x >= behind)).any():
        raise ValueError("ScenarioBatch.own_ahead_x must be ordered: each vehicle at or ahead of the one behind it")


def start(batch):
    """``(x, v)`` ``(B, K)`` column-major: the own lane's initial states, ``L0`` first (``+inf``: none)."""
    if batch.own_ahead_x is None:
        return np.asfortranarray(batch.l0_x[:, None].astype(float)), np.asfortranarray(batch.l0_v[:, None] * 1.0)
    x = np.column_stack([batch.l0_x, batch.own_ahead_x]).astype(float)
    v = np.column_stack([batch.l0_v, batch.own_ahead_v]).astype(float)
    return np.asfortranarray(x), np.asfortranarray(np.where(np.isfinite(x), v, 0.0))


# The connected one's task, compiled into the closed loop's rows (sim/_fast_world.py).
jitable(own_task)
