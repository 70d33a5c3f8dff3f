"""Who is responsible for each scenario's first collision and first ``p_m`` violation (:mod:`safelane.blame`'s rule),
recorded while the closed loop runs (``simulate_batch(..., blame=True)``).

The simulator's world is the paper's: only the ego changes lanes; F, L1, L2, … drive in the target lane (centre
``y = lane_width``), an own-lane leader L0 in the ego's lane (``y = 0``), all ``vehicle_length × vehicle_width``.
Every pair (ego, vehicle) is followed by the running rule (:func:`safelane.blame.update`) at every period boundary —
the samples are the control periods, the exact states there; the collision itself is found in continuous time inside
a period (:mod:`.checks`), and judged at the end of that period. Two followers per pair: one for collisions (RSS's
safe distances), one for ``p_m`` violations (the distances raised to the margins that define one: ``p_m −
vehicle_length`` bumper to bumper, and ``y_safe`` edge to edge, how far a lane-centred vehicle's edge is from an ego
whose body has just reached the lane line). RSS's parameters: ``RssParams.matched(params)`` (this world's limits, ρ
one period) unless given.

The partner of an event is read from what the checks already keep: F where the running minimum gap to F fell below
the vehicle length (``p_m`` for a violation) in that period, else L1 likewise, else L0 where its own flag turned,
else the target-lane vehicle nearest to the ego at the period's end. With the rule, nobody but the ego moves
laterally here, so the lateral clause always names the ego: it entered the target lane (or reached the lane line)
while longitudinally unsafe; the longitudinal clause the rear vehicle — F for an F that ran into an ego already in
its lane at a safe distance, the ego for one that ran into L1.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..baselines.rss import RssParams
from ..blame import NONE, BlameState, Track, start, update, verdict

#: ``partner`` codes beyond the target-lane slots ``0`` (F), ``1`` (L1), …: none, and L0.
NO_PARTNER, OWN_LANE = -1, -2


@dataclass(frozen=True)
class Events:
    """Per scenario: the first event's ``partner`` (slot, :data:`OWN_LANE` or :data:`NO_PARTNER`), and the rule's
    ``responsible``, ``clause``, ``blame_t`` (:class:`safelane.blame.Blame`'s codes)."""

    partner: np.ndarray
    responsible: np.ndarray
    clause: np.ndarray
    blame_t: np.ndarray

    @classmethod
    def none(cls, n: int) -> Events:
        return cls(np.full(n, NO_PARTNER, np.int64), np.zeros(n, np.int8), np.zeros(n, np.int8), np.full(n, np.nan))


@dataclass(frozen=True)
class SimBlame:
    """The followers of every pair (``(B, K)`` target lane, ``(B,)`` L0 or ``None``) and the events so far."""

    rss: RssParams
    lane: BlameState
    lane_pm: BlameState
    own: BlameState | None
    own_pm: BlameState | None
    collision: Events
    pm: Events


def _tracks(prm, ego, x, v, y):
    ex, ey, evx, evy = (np.asarray(q, float)[:, None] for q in ego)
    size = (prm.vehicle_length, prm.vehicle_width)
    return Track(ex, ey, evx, evy, *size), Track(x, np.full_like(x, y), v, np.zeros_like(x), *size)


def _observe(sb: SimBlame, t: float, prm, valid, ego, x, v, l0) -> SimBlame:
    pm_lon, pm_lat = prm.p_m - prm.vehicle_length, prm.y_safe
    e, o = _tracks(prm, ego, x, v, prm.lane_width)
    lane = update(sb.lane, t, e, o, sb.rss, active=valid)
    lane_pm = update(sb.lane_pm, t, e, o, sb.rss, min_lon_gap_m=pm_lon, min_lat_gap_m=pm_lat, active=valid)
    own, own_pm = sb.own, sb.own_pm
    if own is not None:
        l0_x, l0_v = l0[0][:, 0], l0[1][:, 0]  # L0, the own lane's nearest: the ego's only partner there
        present = np.isfinite(l0_x)
        e, o = _tracks(prm, ego, np.where(present, l0_x, 0.0)[:, None], l0_v[:, None], 0.0)
        e, o = (Track(*(np.asarray(q)[:, 0] if np.ndim(q) == 2 else q for q in tr)) for tr in (e, o))
        own = update(own, t, e, o, sb.rss, active=present)
        own_pm = update(own_pm, t, e, o, sb.rss, min_lon_gap_m=pm_lon, min_lat_gap_m=pm_lat, active=present)
    return dataclasses.replace(sb, lane=lane, lane_pm=lane_pm, own=own, own_pm=own_pm)


def begin(b, prm, rss: RssParams | None, ego, x, v, l0) -> SimBlame:
    """The followers after the first sample (the batch's start)."""
    n, k = x.shape
    own = None if l0 is None else start((n,))
    sb = SimBlame(rss or RssParams.matched(prm), start((n, k)), start((n, k)), own, own, Events.none(n),
                  Events.none(n))  # fmt: skip
    return _observe(sb, 0.0, prm, b.valid, ego, x, v, l0)


def _first(events: Events, flipped, partner, lane: BlameState, own: BlameState | None, rss) -> Events:
    rows = np.flatnonzero(flipped & (events.partner == NO_PARTNER))
    if rows.size == 0:
        return events
    cols = partner[rows]
    on_lane = cols >= 0
    out = [a.copy() for a in (events.partner, events.responsible, events.clause, events.blame_t)]
    out[0][rows] = cols
    picked = (lane.take((rows, np.maximum(cols, 0))).take(on_lane), None if own is None else own.take(rows[~on_lane]))
    for mask, state in zip((on_lane, ~on_lane), picked, strict=True):
        if state is None or not mask.any():
            continue
        sel = rows[mask]
        v = verdict(state, rss)
        out[1][sel], out[2][sel], out[3][sel] = v.responsible, v.clause, v.blame_t
    return Events(*out)


def step(sb: SimBlame, s, new, b, prm) -> SimBlame:
    """The followers after the period from state ``s`` to ``new`` (its end is the new sample), and the verdict for
    each scenario whose first collision or first ``p_m`` violation happened in it."""
    sb = _observe(sb, new.t, prm, b.valid, new.ego, new.x, new.v, new.l0)
    length = prm.vehicle_length
    dx = np.where(b.valid, np.abs(new.x - new.ego[0][:, None]), np.inf)
    nearest = np.argmin(dx, 1)
    none = np.zeros(len(dx), bool)
    own_hit = none if new.l0 is None else new.l0_collided & ~s.l0_collided
    own_pm = none if new.l0 is None else new.l0_violated & ~s.l0_violated

    def partner(limit, own_flipped):
        return np.select([new.min_gap_f < limit, new.min_gap_l1 < limit, own_flipped], [0, 1, OWN_LANE], nearest)

    col, pm = partner(length, own_hit), partner(prm.p_m, own_pm)
    collision = _first(sb.collision, new.collided & ~s.collided, col, sb.lane, sb.own, sb.rss)
    violation = _first(sb.pm, new.violated & ~s.violated, pm, sb.lane_pm, sb.own_pm, sb.rss)
    return dataclasses.replace(sb, collision=collision, pm=violation)


def no_events(n: int) -> dict:
    """:func:`columns` of ``n`` scenarios without an event."""
    empty = np.full(n, "", object)
    return {f"{kind}_{name}": (np.full(n, np.nan) if name == "blame_t" else empty.copy())
            for kind in ("collision", "pm") for name in ("partner", "blame", "blame_clause", "blame_t")}  # fmt: skip


def columns(sb: SimBlame) -> dict:
    """The results table's blame columns: per event kind (``collision``, ``pm``) ``<kind>_partner`` (``F``, ``L1``,
    …, ``L0``, ``""``), ``<kind>_blame`` (``ego``, ``other``, ``both``, ``""``), ``<kind>_blame_clause`` and
    ``<kind>_blame_t`` [s]."""
    from ..blame import CLAUSES, RESPONSIBLE

    out = {}
    for kind, ev in (("collision", sb.collision), ("pm", sb.pm)):
        names = np.array(["", "L0", "F", *(f"L{i}" for i in range(1, sb.lane.seen.shape[1]))], object)
        out[f"{kind}_partner"] = names[np.where(ev.partner == OWN_LANE, 1, np.where(ev.partner < 0, 0, ev.partner
                                                                                        + 2))]  # fmt: skip
        who = np.array(["" if r is None else r for r in RESPONSIBLE], object)
        out[f"{kind}_blame"] = who[ev.responsible]
        out[f"{kind}_blame_clause"] = np.array(CLAUSES, object)[ev.clause]
        out[f"{kind}_blame_t"] = np.where(ev.responsible != NONE, ev.blame_t, np.nan)
    return out
