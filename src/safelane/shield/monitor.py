"""The assumption monitor: every period, did the others do what the ego's held plan assumed?

The guarantee holds while the assumptions hold. The monitor makes a breach visible instead of silent: at the end
of each period it compares what the target-lane vehicles did with what the analysis assumed, records which
assumption broke and when, and — with ``SimConfig.monitor`` on — makes the supervisor use the most conservative
assumptions from the next period on (``L1`` at ``a_x_d``, ``F`` aggressive). Kinds (:data:`BREACH_KINDS`):

* ``l1_decel`` — ``L1`` braked harder than the deceleration the held plan assumed for it;
* ``leader_bound`` — a connected leader braked harder than its chain bound (an *unexpected* promise violation);
* ``last_decel`` — ``L(N+1)`` braked beyond ``a_x_d``;
* ``follower`` — an ``F`` the held plan took for collaborative did not yield: with the ego ahead of it, it
  accelerated beyond what a responsible follower of the ego may (a wrong assessment, or an ``F`` that ignores
  the ego);
* ``stale_v2x`` — a connected leader's or F's latest message was stale (lost or late, ``safelane.sim.link``): the
  staleness fallback already treats that sender as non-connected; the monitor records it and, from then on,
  assumes the worst of everyone.

Everything compared is what the ego can observe at the period's end (accelerations from consecutive V2X or
sensed states); the comparison itself is exact up to ``TOL_MPS2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from .behaviours import responsible_bound

BREACH_KINDS = ("l1_decel", "leader_bound", "last_decel", "follower", "stale_v2x")
#: Accelerations within this of the assumed bound count as inside it (round-off of the behaviours' closed forms).
TOL_MPS2 = 1e-6


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


def observe_breaches(
    prev: Breach,
    s,
    acc,
    bounds,
    plan_l1_decel,
    plan_f_aggr,
    active,
    prm: Params,
    t_end: float,
    last_switch,
    last_slot,
    stale=None,
) -> Breach:
    """The record after one period: ``s`` the state at its start, ``acc (B, K)`` what the others applied (and
    ``last_switch``, L(N+1)'s second segment inside the period, if any), ``bounds (B, K)`` the chain's bounds at
    its start, ``plan_l1_decel``/``plan_f_aggr`` what the held plan assumed, ``active`` the lane change under way."""
    bsz, k = acc.shape
    decel = -acc
    if last_switch is not None:  # the harder of the two segments
        decel = np.maximum(decel, np.where(last_switch[0] < prm.dt, -last_switch[1], -np.inf))
    slots = np.arange(k)[None, :]
    is_last = slots == last_slot[:, None]
    connected = (slots >= 1) & (slots < last_slot[:, None])
    flags = np.zeros((bsz, len(BREACH_KINDS)), bool)
    flags[:, 0] = active & (decel[:, 1] > plan_l1_decel + TOL_MPS2)
    flags[:, 1] = (connected & (decel > bounds + TOL_MPS2)).any(1)
    flags[:, 2] = (is_last & (decel > prm.a_x_d + TOL_MPS2)).any(1)
    ex, evx = s.ego[0], s.ego[2]
    gap = ex - s.x[:, 0]
    with np.errstate(all="ignore"):
        limit = np.maximum(responsible_bound(gap - prm.p_m, s.v[:, 0], evx, np.full(bsz, prm.a_x_d), prm), -prm.a_x_d)
    flags[:, 3] = active & ~plan_f_aggr & (gap > 0.0) & (acc[:, 0] > limit + TOL_MPS2)
    if stale is not None:
        flags[:, 4] = active & stale
    new = flags & ~prev.flags
    first = np.where(np.isnan(prev.first_s) & new.any(1), t_end, prev.first_s)
    return Breach(flags=prev.flags | flags, first_s=first)
