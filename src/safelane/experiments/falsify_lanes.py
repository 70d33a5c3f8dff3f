"""The multi-lane falsifier's referee: the rows of :mod:`.falsify_lanes_world` (its world, the other vehicles'
behaviours and what the shield is given) run in closed loop with the shield, and every collision and ``p_m``
violation judged.

**Measured**, in continuous time sampled every ``dt / substeps``: a *collision* is the ego's body overlapping
another's (``|dx| < vehicle_length``, ``|dy| < vehicle_width``); a *``p_m`` violation* is ``|dx| < p_m`` (to 1 nm,
as the simulator's) while the two bodies overlap a common lane by more than 1 nm — toward a vehicle out of the
target lane only until the lane change completes (the paper's conflict zones: the target lane's vehicles once the
ego's body is in the target lane, the original lane's until the change completes). Each event is judged by the blame
rule (:func:`safelane.blame.blame`, ``RssParams.matched`` with the front vehicle's ``brake_max`` at ``a_o_d``) on
the period samples up to it: ``ego_responsible`` counts ``"ego"`` and ``"both"``.

Vectorised over the rows; the loop runs over periods. Every draw comes from ``default_rng([seed, stream, batch])``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._motion import advance
from ..baselines.rss import RssParams
from ..blame import Track, blame
from ..params import Params
from ..safety._backend import FEASIBILITY_TOL_M
from ..safety.lateral import LATERAL_TOL_M
from ..shield import ShieldConfig
from ..shield.command import Command
from ..shield.decision import COMPLETED
from .falsify_lanes_world import (
    ENTRANTS,
    GOAL,
    SLOTS,
    draw,
    initial_state,
    lanes_overlapped,
    may_enter,
    nominal,
    others_accels,
    share_lane,
    situation,
    starts_inside,
)


@dataclass(frozen=True)
class LaneWorld:
    """The world's settings."""

    params: Params = field(default_factory=Params)
    #: The assessment is the truth (F is aggressive here): the guarantee assumes an accurate one, as in the paper
    #: world's falsifier. (The ``observed`` assessment reads an F braking for its own leader as yielding.)
    config: ShieldConfig = field(default_factory=lambda: ShieldConfig(assessment="truth"))
    horizon_s: float = 12.0
    substeps: int = 10


def _ego_at(ego, piece, tau):
    """The ego's state ``tau`` into the period under the command's pieces ``(dur, a_x, a_y)``."""
    dur, ax, ay = piece
    x, y, vx, vy = ego
    start = np.zeros(len(x))
    for k in range(dur.shape[1]):
        h = np.clip(tau - start, 0.0, dur[:, k])
        x, vx_new = advance(x, vx, ax[:, k], h)
        y, vy = y + vy * h + 0.5 * ay[:, k] * h * h, vy + ay[:, k] * h
        vx = vx_new
        start = start + dur[:, k]
    return x, y, vx, vy


@dataclass
class Outcome:
    """Per row: events, their blame, whether the row stayed inside the assumptions."""

    started: np.ndarray  # the start is inside the assumptions (else the row is not judged)
    inside: np.ndarray  # started, and every entrant kept the entering rule
    collided: np.ndarray
    violated: np.ndarray
    ego_collision: np.ndarray  # the ego responsible for a collision (alone or with the other)
    ego_violation: np.ndarray
    entries: np.ndarray  # entrants that entered
    breached: np.ndarray  # the monitor flagged a breach
    completed: np.ndarray
    min_ratio: np.ndarray  # smallest |dx| / p_m over the laterally conflicting samples
    first: dict  # per event kind: (B, 5) first event time (NaN: none)
    tracks: dict  # x, y, vx, vy: (B, 6, T + 1) at the period starts, the ego first, then SLOTS
    behaviour: np.ndarray  # (B, T) the shield's behaviour code per period


def simulate(spec: dict, world: LaneWorld, observer=None) -> Outcome:
    """Run the rows of ``spec`` to the horizon (module docstring). ``observer(t, situation, decision)``, if given,
    sees every period (a trace)."""
    from ..shield import Shield

    prm = world.params
    dt, sub = prm.dt, world.substeps
    n = len(spec["ego_v"])
    inside = starts_inside(spec, prm)
    ego, x, v, y = initial_state(spec, prm)
    vy = np.zeros((n, 5))
    shield = Shield(prm, config=world.config)
    shield.reset(situation(0.0, ego, x, v, y, vy, spec, prm))
    inside &= np.asarray(shield.state.plan.feasible, bool)
    started = inside.copy()
    periods = round(world.horizon_s / dt)
    entered = np.zeros((n, 5), bool)
    entry_t = np.full((n, 5), np.inf)
    entry_ahead = np.zeros((n, 5), bool)
    entry_ok = np.ones((n, 5), bool)
    completed = np.zeros(n, bool)
    breached = np.zeros(n, bool)
    first = {"collision": np.full((n, 5), np.nan), "violation": np.full((n, 5), np.nan)}
    min_ratio = np.full(n, np.inf)
    rec = {q: np.full((n, 6, periods + 1), np.nan) for q in ("x", "y", "vx", "vy")}
    behaviour = np.zeros((n, periods), np.int8)
    for p in range(periods):
        t = p * dt
        for q, arrs in zip(("x", "y", "vx", "vy"), ((ego[0], x), (ego[1], y), (ego[2], v), (ego[3], vy)), strict=True):
            rec[q][:, 0, p], rec[q][:, 1:, p] = arrs
        # entries: the first period start at which an entrant's body overlaps its new lane
        for i in ENTRANTS:
            now = ~entered[:, i] & np.isfinite(x[:, i]) & lanes_overlapped(y[:, i], prm, GOAL[i])
            if now.any():
                ok = may_enter(i, x, v, y, vy, ego, prm, 0.0)
                entry_ok[:, i] &= ~now | ok
                entry_t[:, i] = np.where(now, t, entry_t[:, i])
                entry_ahead[:, i] |= now & (x[:, i] > ego[0])
                entered[:, i] |= now
        seen = situation(t, ego, x, v, y, vy, spec, prm)
        d = shield.step(seen, nominal(t, ego, spec, prm))
        if observer is not None:
            observer(t, seen, d)
        completed |= d.behaviour == COMPLETED
        behaviour[:, p] = d.behaviour
        breached |= d.breach.any
        ax, ay = others_accels(t, ego, x, v, y, vy, entered, entry_t, entry_ahead, completed, spec, prm)
        piece = Command.of(d).piece(dt)
        for s in range(1, sub + 1):
            tau = dt * s / sub
            ex, ey, _, _ = _ego_at(ego, piece, tau)
            xs, _ = advance(x, v, ax, tau)
            ys = y + vy * tau + 0.5 * ay * tau * tau
            dx, dy = np.abs(xs - ex[:, None]), np.abs(ys - ey[:, None])
            dx = np.where(np.isfinite(xs), dx, np.inf)
            # p_m counts toward a vehicle whose body shares a lane with the ego's (a body edge on a lane line, to
            # 1 nm, is in neither), out of the target lane only until the lane change completes (the paper's rule
            # for the original lane, docs/simulator.md)
            lat = share_lane(ys, ey[:, None], prm, LATERAL_TOL_M)
            lat &= ~(completed[:, None] & ~lanes_overlapped(ys, prm, 1))
            for kind, hit in (("collision", (dx < prm.vehicle_length) & (dy < prm.vehicle_width)),
                              ("violation", (dx < prm.p_m - FEASIBILITY_TOL_M) & lat)):  # fmt: skip
                new = hit & np.isnan(first[kind])
                first[kind] = np.where(new, t + tau, first[kind])
            min_ratio = np.minimum(min_ratio, np.where(lat, dx / prm.p_m, np.inf).min(1))
        ego = _ego_at(ego, piece, dt)
        x, v = advance(x, v, ax, dt)
        y, vy = y + vy * dt + 0.5 * ay * dt * dt, vy + ay * dt
    for q, arrs in zip(("x", "y", "vx", "vy"), ((ego[0], x), (ego[1], y), (ego[2], v), (ego[3], vy)), strict=True):
        rec[q][:, 0, periods], rec[q][:, 1:, periods] = arrs
    inside &= entry_ok.all(1)
    times = dt * np.arange(periods + 1)
    verdict = {kind: _judge(rec, times, first[kind], prm, kind) for kind in first}
    collided = ~np.isnan(first["collision"]).all(1)
    violated = ~np.isnan(first["violation"]).all(1)
    return Outcome(started, inside, collided, violated, verdict["collision"], verdict["violation"], entered.sum(1),
                   breached,
                   completed, min_ratio, first, rec, behaviour)  # fmt: skip


def _judge(rec, times, first, prm: Params, kind: str) -> np.ndarray:
    """``(B,)`` whether the ego is responsible for any of the row's events of ``kind`` (the blame rule on the period
    samples up to each event: the period's end)."""
    rows, slots = np.nonzero(~np.isnan(first))
    out = np.zeros(first.shape[0], bool)
    if rows.size == 0:
        return out
    rss = RssParams.matched(prm).model_copy(update={"brake_max": prm.others_decel})
    event_t = np.ceil(first[rows, slots] / prm.dt - 1e-9) * prm.dt
    size = (prm.vehicle_length, prm.vehicle_width)
    ego = Track(*(rec[q][rows, 0] for q in ("x", "y", "vx", "vy")), *size)
    other = Track(*(rec[q][rows, 1 + slots] for q in ("x", "y", "vx", "vy")), *size)
    gaps = {} if kind == "collision" else {"min_lon_gap_m": prm.p_m - prm.vehicle_length,
                                           "min_lat_gap_m": 0.5 * (prm.lane_width - prm.vehicle_width)}  # fmt: skip
    verdict = blame(np.broadcast_to(times, ego.x.shape), ego, other, event_t, rss, **gaps)
    np.logical_or.at(out, rows, verdict.ego_responsible)
    return out


def take(spec: dict, rows) -> dict:
    """The rows ``rows`` of a spec (a replay of one scenario)."""
    return {k: np.asarray(a)[rows] for k, a in spec.items()}


__all__ = ["SLOTS", "LaneWorld", "Outcome", "draw", "simulate", "starts_inside", "take"]
