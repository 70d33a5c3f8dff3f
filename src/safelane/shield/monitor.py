"""The assumption monitor: every period, did the others do what the ego's held plan assumed?

The guarantee holds while the assumptions hold. The monitor makes a breach visible instead of silent: at the start
of each period it compares what the target-lane vehicles did in the last one with what the analysis assumed,
records which assumption broke and when, and — with ``ShieldConfig.monitor`` on — makes the shield use the most
conservative assumptions from then on (``L1`` at ``a_x_d``, ``F`` aggressive). Kinds (:data:`BREACH_KINDS`):

* ``l1_decel`` — ``L1`` braked harder than the deceleration the held plan assumed for it;
* ``leader_bound`` — a connected leader braked harder than its chain bound (an *unexpected* promise violation);
* ``last_decel`` — a non-connected leader braked beyond the others' maximum ``a_o_d`` (``a_x_d`` unless set):
  ``L(N+1)`` in the target lane or, in the cumulative comparison, ``L0`` in the ego's own lane;
* ``follower`` — an ``F`` the held plan took for collaborative did not yield: with the ego ahead of it, it
  accelerated beyond what a responsible follower of the ego may (a wrong assessment, or an ``F`` that ignores
  the ego);
* ``stale_v2x`` — a connected leader's or F's latest message was stale (lost or late, ``safelane.sim.link``): the
  staleness fallback already treats that sender as non-connected; the monitor records it and, from then on,
  assumes the worst of everyone.

Everything compared is what the ego observes: consecutive situations (positions of the chain and F) against the
positions the assumptions allow; exact up to ``TOL_M``.

**Cumulative comparison** (where the situation carries a sensing-error box): the per-period comparison widens each
period's prediction by the box, so an excess smaller than the box per period — a leader braking 1 m/s² beyond its
assumed maximum for seconds — is never seen. So each period the monitor also compares every watched vehicle with the
worst case the plans held since the :class:`Anchor` (taken with the first plan) assumed: the chain at its bounds
(``L1`` at the plans' deceleration), ``L0`` at its worst case, an ``F`` the plan takes for aggressive at ``+a_x_a``,
each at the largest deceleration any plan held since the anchor assumed; each must stay at or ahead of (leaders) / at
or behind (F) where that worst case puts it at the time since the anchor, the sensing box counted once (the anchor at
the analysis' corner, the observation at its far corner), not once per period. Kinds as above (``L0``:
``last_decel``). A chain that changed (length or connected count) re-anchors its row, F re-anchors where the plan's
assumption about it changed, a new L0 where there was none; a collaborative ``F`` keeps the per-period check (its
responsible limit changes every period).

The comparison per vehicle is written once
(:func:`braked_harder`, :func:`pushed_harder`, backend-generic and marked ``jitable``): :func:`observe_breaches`
evaluates it on NumPy arrays, the compiled monitor (:mod:`._fast_monitor`) and the compiled closed loop row by row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._motion import advance, advance_core
from ..params import Params
from ..safety._backend import ARRAY, INF, jitable
from ..safety.chain import braked_position
from ..safety.evasion import fast_kernel
from ..tolerances import MONITOR_TOL_M

BREACH_KINDS = ("l1_decel", "leader_bound", "last_decel", "follower", "stale_v2x")
#: Positions within this of the assumed worst case count as inside it (round-off).
TOL_M = MONITOR_TOL_M


@dataclass(frozen=True)
class Breach:
    """The monitor's record per scenario: which kinds broke (``flags (B, len(BREACH_KINDS))``) and when the first
    breach was observed (``first_s``, NaN if never)."""

    flags: np.ndarray
    first_s: np.ndarray

    @classmethod
    def none(cls, batch: int) -> Breach:
        return cls(flags=np.zeros((batch, len(BREACH_KINDS)), bool), first_s=np.full(batch, np.nan))

    @property
    def any(self) -> np.ndarray:
        return self.flags.any(1)


@dataclass(frozen=True)
class Snapshot:
    """What the monitor needs from the previous period: the chain, F and the ego, the chain's bounds and what the
    held plan assumed (``(B,)`` or ``(B, M)``)."""

    chain_x: np.ndarray
    chain_v: np.ndarray
    bounds: np.ndarray
    n_connected: np.ndarray
    f_x: np.ndarray
    f_v: np.ndarray
    f_limit: np.ndarray  # the largest acceleration a responsible follower of the ego could apply
    plan_l1_decel: np.ndarray
    plan_f_aggr: np.ndarray
    active: np.ndarray
    anchor: Anchor | None = None  # the cumulative comparison's (with a sensing box), else None


@dataclass(frozen=True)
class Anchor:
    """The worst case the held plan assumed, at the moment it was made (the cumulative comparison; ``(B,)`` or
    ``(B, M)``): states at the analysis' corner of the sensing box, each vehicle's assumed maximum deceleration."""

    t: np.ndarray  # when the chain was anchored [s]
    chain_x: np.ndarray
    chain_v: np.ndarray
    bounds: np.ndarray  # the chain's bounds then
    l1_decel: np.ndarray  # the plan's worst case for L1
    n_connected: np.ndarray
    f_x: np.ndarray
    f_v: np.ndarray
    f_accel: np.ndarray  # a_x_a where the plan took F for aggressive, +inf (not compared) where not
    f_t: np.ndarray  # when F was anchored
    own_x: np.ndarray  # L0, +inf where none
    own_v: np.ndarray
    own_decel: np.ndarray
    own_t: np.ndarray  # when L0 was anchored

    def carried(self, now: Anchor) -> Anchor:
        """The anchor for the next period: the states stay those of the anchor, each assumed deceleration is raised
        to the largest any plan held since then assumed (``now``'s: a vehicle that never braked harder than that is
        at or ahead of braking at it from the anchor — sound over any number of plans, so a new plan does not reset
        the history). Taken from ``now``: every row whose chain changed (length or number connected), F where the
        plan's assumption about it changed, L0 where there was none."""
        if self.chain_x.shape != now.chain_x.shape:
            return now
        renew, renew_f, renew_own = anchor_renewal(ARRAY, self.n_connected, now.n_connected, self.f_accel,
                                                   now.f_accel, self.own_x)  # fmt: skip
        renew = np.asarray(renew)

        def pick(rows, a, b, raised=False):
            return anchor_carry(ARRAY, rows.reshape(rows.shape + (1,) * (np.ndim(a) - 1)), a, b, raised)

        return Anchor(
            t=pick(renew, self.t, now.t), chain_x=pick(renew, self.chain_x, now.chain_x),
            chain_v=pick(renew, self.chain_v, now.chain_v), bounds=pick(renew, self.bounds, now.bounds, True),
            l1_decel=pick(renew, self.l1_decel, now.l1_decel, True), n_connected=now.n_connected,
            f_x=pick(renew_f, self.f_x, now.f_x), f_v=pick(renew_f, self.f_v, now.f_v), f_accel=now.f_accel,
            f_t=pick(renew_f, self.f_t, now.f_t), own_x=pick(renew_own, self.own_x, now.own_x),
            own_v=pick(renew_own, self.own_v, now.own_v), own_t=pick(renew_own, self.own_t, now.own_t),
            own_decel=pick(renew_own, self.own_decel, now.own_decel, True),
        )  # fmt: skip


#: :func:`observe_breaches` runs the compiled kernel (:mod:`._fast_monitor`) from this many scenarios on.
FAST_MIN_ROWS = 64


def monitor_kernel():
    """The compiled monitor's module :mod:`._fast_monitor`, or ``None`` where
    :func:`~safelane.safety.evasion.fast_kernel` is ``None`` (numba missing, or ``SAFELANE_NO_NUMBA=1``)."""
    if fast_kernel() is None:
        return None
    from . import _fast_monitor

    return _fast_monitor


def observe_breaches(prev: Breach, last, situation, prm: Params, t_now: float) -> Breach:
    """The record after one period: ``last`` (:class:`~safelane.shield.core.Snapshot`) is what the shield knew and
    assumed at the period's start, ``situation`` what it sees at its end. A vehicle that braked no harder than
    assumed is at or ahead of the position braking at the assumed deceleration would give it (exact, with
    stopping); an F no more pushy than a responsible follower of the ego is at or behind the position its
    responsible limit would give it. Positions are compared to ``TOL_M``. Where the chain changed length (a
    vehicle left or joined it) the leader comparisons are skipped for that period. From :data:`FAST_MIN_ROWS`
    scenarios on it runs the compiled kernel (:mod:`._fast_monitor`) where numba imports and ``SAFELANE_NO_NUMBA`` is
    not ``1``: the same flags, the NumPy path below is the reference."""
    bsz = len(prev.first_s)
    kernel = monitor_kernel() if bsz >= FAST_MIN_ROWS else None
    if last.anchor is not None:  # the cumulative comparison first: its flags join the period's
        prev = _with_flags(prev, anchor_flags(last.anchor, last.active, situation, prm, t_now, kernel), t_now)
    if kernel is not None:
        return kernel.observe_breaches(prev, last, situation, prm, t_now)
    flags = np.zeros((bsz, len(BREACH_KINDS)), bool)
    dt = prm.dt
    if situation.chain_x.shape == last.chain_x.shape:
        now = situation.chain_x
        behind = braked_harder(ARRAY, now, last.chain_x, last.chain_v, last.bounds, dt, TOL_M)
        l1 = braked_harder(ARRAY, now[:, 0], last.chain_x[:, 0], last.chain_v[:, 0], last.plan_l1_decel, dt, TOL_M)
        flags[:, 0] = last.active & l1
        slots = np.arange(behind.shape[1])[None, :]
        flags[:, 1] = (behind & (slots < last.n_connected[:, None])).any(1)
        flags[:, 2] = (behind & (slots == last.n_connected[:, None])).any(1)
    with np.errstate(over="ignore"):  # as _motion.advance: a vanishing deceleration stops at the horizon
        flags[:, 3] = pushed_harder(ARRAY, situation.f_x, last.f_x, last.f_v, last.f_limit, dt, TOL_M)
    new = flags & ~prev.flags
    first = np.where(np.isnan(prev.first_s) & new.any(1), t_now, prev.first_s)
    return Breach(flags=prev.flags | flags, first_s=first)


def _with_flags(prev: Breach, flags: np.ndarray, t_now: float) -> Breach:
    new = flags & ~prev.flags
    first = np.where(np.isnan(prev.first_s) & new.any(1), t_now, prev.first_s)
    return Breach(flags=prev.flags | flags, first_s=first)


def anchor_flags(anchor: Anchor, active, situation, prm: Params, t_now: float, kernel=None) -> np.ndarray:
    """``(B, len(BREACH_KINDS))`` the cumulative comparison (module docstring) of ``situation`` (the observation's
    far corner) with ``anchor``, for the ``active`` rows: the same comparisons as the period's
    (:func:`braked_harder`, :func:`pushed_harder`) over the time since the anchor. ``kernel``: the compiled
    monitor's module (:func:`anchor_kernel` there), else NumPy."""
    bsz = len(anchor.t)
    age, age_f, age_own = (np.maximum(t_now - t0, 0.0) for t0 in (anchor.t, anchor.f_t, anchor.own_t))
    same = situation.chain_x.shape == anchor.chain_x.shape
    own = getattr(situation, "own_x", None)
    own_now = np.full(bsz, np.inf) if own is None else own[:, 0]
    if kernel is not None:
        return kernel.anchor_flags(anchor, active, situation.chain_x if same else None, situation.f_x, own_now, age,
                                   age_f, age_own)  # fmt: skip
    flags = np.zeros((bsz, len(BREACH_KINDS)), bool)
    with np.errstate(all="ignore"):
        if same:
            now = situation.chain_x
            behind = braked_harder(ARRAY, now, anchor.chain_x, anchor.chain_v, anchor.bounds, age[:, None], TOL_M)
            slots = np.arange(behind.shape[1])[None, :]
            flags[:, 0] = braked_harder(ARRAY, now[:, 0], anchor.chain_x[:, 0], anchor.chain_v[:, 0],
                                        anchor.l1_decel, age, TOL_M)  # fmt: skip
            flags[:, 1] = (behind & (slots < anchor.n_connected[:, None])).any(1)
            flags[:, 2] = (behind & (slots == anchor.n_connected[:, None])).any(1)
        has_own = np.isfinite(anchor.own_x) & np.isfinite(own_now)
        flags[:, 2] |= has_own & braked_harder(ARRAY, np.where(has_own, own_now, 0.0), np.where(has_own, anchor.own_x,
                                               0.0), anchor.own_v, anchor.own_decel, age_own, TOL_M)  # fmt: skip
        flags[:, 3] = pushed_harder(ARRAY, situation.f_x, anchor.f_x, anchor.f_v, anchor.f_accel, age_f, TOL_M)
    return flags & np.asarray(active, bool)[:, None]


def predicted_positions(snapshot: Snapshot, dt: float):
    """Where the monitor expects the chain and F at the end of the period at the latest/earliest: the chain
    braking at its bounds (lowest positions), F at its responsible limit (highest position)."""
    tx = braked_position(ARRAY, snapshot.chain_x, snapshot.chain_v, snapshot.bounds, dt)
    fx, _ = advance(snapshot.f_x, snapshot.f_v, np.where(np.isinf(snapshot.f_limit), 0.0, snapshot.f_limit), dt)
    return tx, fx


def anchor_renewal(xp, held_nc, now_nc, held_f_accel, now_f_accel, held_own_x):
    """``(renew, renew_f, renew_own)``: which of a row's anchors :meth:`Anchor.carried` takes from the new one — the
    chain where its number connected changed, F also where the plan's assumption about it changed, L0 also where
    there was none (a position not finite). Backend-generic, the one source (the compiled period evaluates it per
    row)."""
    renew = held_nc != now_nc
    no_own = (held_own_x != held_own_x) | (held_own_x == INF) | (held_own_x == -INF)
    return renew, renew | (held_f_accel != now_f_accel), renew | no_own


def anchor_carry(xp, renew, held, now, raised):
    """One anchored value for the next period: ``now`` where ``renew``, else ``held`` — raised to ``now`` where
    ``raised`` (an assumed deceleration: the largest any plan held since the anchor assumed). Backend-generic."""
    return xp.where(renew, now, xp.maximum(held, now) if raised else held)


def braked_harder(xp, now, p, v, decel, dt, tol):
    """The breach test of a vehicle assumed to brake at no more than ``decel`` (a leader at its chain bound, L1 at the
    held plan's deceleration): it is now (``now``) more than ``tol`` behind where braking at ``decel`` from ``(p, v)``
    for ``dt`` would have put it (exact, stopping at rest: :func:`~safelane.safety.chain.braked_position`).
    Backend-generic; every argument broadcasts."""
    return now < braked_position(xp, p, v, decel, dt) - tol


def pushed_harder(xp, now, p, v, limit, dt, tol):
    """The breach test of F: watched (a finite ``limit``, the largest acceleration a responsible follower of the ego
    could apply) and now (``now``) more than ``tol`` ahead of where accelerating at that limit from ``(p, v)`` for
    ``dt`` would have put it (exact, stopping at rest: :func:`safelane._motion.advance_core`). Backend-generic; every
    argument broadcasts."""
    watched = (limit == limit) & (limit != INF) & (limit != -INF)
    highest, _ = advance_core(xp, p, v, xp.where(watched, limit, 0.0), dt)
    return watched & (now > highest + tol)


# The comparisons compiled into the monitor's kernel and the closed loop (safety/_compile.py): the same functions.
jitable(braked_harder, pushed_harder, anchor_renewal, anchor_carry)
