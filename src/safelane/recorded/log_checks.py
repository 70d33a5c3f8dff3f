"""The referee of the closed loop on the log (:mod:`.log_loop`): the ego's exact motion sampled inside a period,
collisions of oriented rectangles, ``p_m`` gaps, and the blame rule.

Everything is in the event's **lane frame** in metres: ``x`` along the road (the recording's), ``y`` lateral from the
centre of the ego's original lane, positive toward the target lane, lanes ``W`` wide (the distance between the two
lanes' centres), lane ``l`` (``0`` the original, ``1`` the target, ``2`` beyond it, ``-1`` on the other side) the
band ``[(l − ½)W, (l + ½)W)``. Arrays are ``(B, V, J)``: events, replayed vehicles, samples inside the period.

**Collision**: the two footprints (rectangles of the recorded length and width, heading along the direction of
motion: the ego's from its velocity, a replayed vehicle's from its displacement over the frame) overlap at a sample
— the separating-axis test, exact for two rectangles at one instant. Samples are :data:`SUBSTEPS` per period; the
ego's positions at them are exact (its piecewise-constant accelerations), a replayed vehicle's are linear between
its recorded frames (a recorded acceleration of 3 m/s² moves it under 4 mm off that line within 0.1 s).

**Blame** (:func:`blame_other`), in the spirit of RSS (the rear vehicle is responsible, unless the other one cut in
too close): a collision (or a ``p_m`` violation) with a replayed vehicle ``R``, while the ego's body is in ``R``'s
lane, is **R's** ("other") iff

1. *rear-end*: ``R`` is behind the ego (its centre behind the ego's) and the ego did not cut in within ``R``'s safe
   distance — the ego was in that lane from the loop's start on, or when its body last entered it the
   bumper-to-bumper gap from ``R`` to the ego was at least RSS's safe longitudinal distance for ``R`` behind the ego;
   or
2. *cut-in*: ``R`` came into the ego's lane (its centre entered a lane the ego's body was in) within the safe
   distance of whichever of the two was behind, and has stayed there.

Safe distances are RSS's with ad-rss's default parameters (another vehicle: response 2 s at up to 3.5 m/s², then
braking at 4 m/s²; the ego: response 1 s; the front vehicle braking at up to 8 m/s²), and never less than the
shield's margin ``p_m`` (as a bumper-to-bumper gap: at a standstill RSS asks for less). Everything else is the
ego's — a conservative split: a contact with a vehicle in a lane the ego's body does not take (the ego
side-swiping, or being side-swiped from a lane it has not entered) counts against the ego.
"""

from __future__ import annotations

import numpy as np

from .._motion import advance
from ..baselines.rss import RssParams, longitudinal_safe_distance

#: Samples per control period for the collision and ``p_m`` checks (every 0.01 s at ``dt = 0.1``).
SUBSTEPS = 10

#: Lane offsets tracked for the blame rule's "when the ego entered that lane": the other side, own, target, beyond.
LANE_OFFSETS = (-1, 0, 1, 2)

#: RSS's parameters for a replayed vehicle's safe distance (ad-rss's documented starting values).
BLAME_RSS = RssParams()


def sample_segments(ego, dur, ax, ay, taus):
    """The ego's exact states at the times ``taus`` ``(J,)`` inside a period of piecewise-constant accelerations
    ``(dur, ax, ay)``, each ``(B, S)`` (:meth:`safelane.shield.command.Command.piece`): ``(x, y, vx, vy)``, each
    ``(B, J)``; longitudinally it stops rather than reverses, laterally it is free (as the command's own
    integration, :func:`safelane.shield.command.segment_states`)."""
    x, y, vx, vy = (np.repeat(np.asarray(q, float)[:, None], len(taus), 1) for q in ego)
    start = np.concatenate([np.zeros((dur.shape[0], 1)), np.cumsum(dur, 1)[:, :-1]], 1)
    for k in range(dur.shape[1]):
        h = np.clip(taus[None, :] - start[:, k : k + 1], 0.0, dur[:, k : k + 1])
        a_x, a_y = ax[:, k : k + 1], ay[:, k : k + 1]
        x, vx = advance(x, vx, a_x, h)
        y, vy = y + vy * h + 0.5 * a_y * h * h, vy + a_y * h
    return x, y, vx, vy


def boxes_overlap(x1, y1, th1, l1, w1, x2, y2, th2, l2, w2):
    """Do two rectangles (centre, heading [rad], length, width) overlap? The separating-axis test on the four
    edge normals; arrays broadcast. Touching edges do not overlap."""
    dx, dy = x2 - x1, y2 - y1
    c1, s1, c2, s2 = np.cos(th1), np.sin(th1), np.cos(th2), np.sin(th2)
    separated = np.zeros(np.broadcast_shapes(np.shape(dx), np.shape(l2)), bool)
    for ux, uy in ((c1, s1), (-s1, c1), (c2, s2), (-s2, c2)):
        r1 = 0.5 * l1 * np.abs(ux * c1 + uy * s1) + 0.5 * w1 * np.abs(-ux * s1 + uy * c1)
        r2 = 0.5 * l2 * np.abs(ux * c2 + uy * s2) + 0.5 * w2 * np.abs(-ux * s2 + uy * c2)
        separated |= np.abs(dx * ux + dy * uy) >= r1 + r2
    return ~separated


def bumper_gap(ego_x, ego_len, x, length):
    """Bumper-to-bumper gap [m] between the ego and each replayed vehicle along the road (negative: they overlap
    longitudinally), and whether that vehicle is behind the ego (its centre behind the ego's)."""
    behind = x < ego_x
    gap = np.where(behind, (ego_x - 0.5 * ego_len) - (x + 0.5 * length), (x - 0.5 * length) - (ego_x + 0.5 * ego_len))
    return gap, behind


#: :func:`lane_of` of an unknown position (a vehicle not recorded then).
NO_LANE = -99


def lane_of(y, lane_w):
    """The lane offset (``0`` original, ``1`` target, ...) of a lateral position in the lane frame (:data:`NO_LANE`
    where ``y`` is not finite)."""
    y = np.asarray(y, float)
    ok = np.isfinite(y)
    return np.where(ok, np.floor(np.where(ok, y, 0.0) / lane_w + 0.5), NO_LANE).astype(np.int64)


def body_in_lane(ego_y, ego_w, lane, lane_w):
    """The ego's body (lateral extent ``ego_y ± ego_w/2``) overlaps lane ``lane``'s band."""
    lo, hi = (lane - 0.5) * lane_w, (lane + 0.5) * lane_w
    return (ego_y + 0.5 * ego_w > lo) & (ego_y - 0.5 * ego_w < hi)


def rear_safe_distance(v_ego, v_rear):
    """RSS's safe distance [m] (bumper to bumper) for a replayed vehicle at ``v_rear`` behind the ego at ``v_ego``
    (:data:`BLAME_RSS`)."""
    p = BLAME_RSS
    return longitudinal_safe_distance(np.maximum(v_ego, 0.0), np.maximum(v_rear, 0.0), p.response_time_other,
                                      p.accel_max, p.brake_min, p.brake_max)  # fmt: skip


def ego_safe_distance(v_front, v_ego):
    """RSS's safe distance [m] (bumper to bumper) for the ego at ``v_ego`` behind a replayed vehicle at
    ``v_front``."""
    p = BLAME_RSS
    return longitudinal_safe_distance(np.maximum(v_front, 0.0), np.maximum(v_ego, 0.0), p.response_time_ego,
                                      p.accel_max, p.brake_min, p.brake_max)  # fmt: skip


class EntryLog:
    """For the blame rule, who came into whose lane how: per event and lane offset, whether the ego entered that
    lane cleanly — it was in it from the start, or when its body last entered it every replayed vehicle behind was
    at least its RSS safe distance back (per vehicle: ``clean[b, lane, v]``); per replayed vehicle, whether it cut in
    (``cut_in[b, v]``: its centre's last lane change took it into a lane the ego's body was in, within the safe
    distance of the rear one of the two; cleared when the ego enters that lane anew)."""

    def __init__(self, ego_y, ego_w, lane_w, other_lane, margin_m: float):
        self.margin_m = margin_m
        lanes = np.array(LANE_OFFSETS)
        self.inside = body_in_lane(ego_y[:, None], ego_w[:, None], lanes[None, :], lane_w[:, None])  # (B, 4)
        self.clean = np.ones((len(ego_y), len(lanes), other_lane.shape[1]), bool)  # there since the start: clean
        self.lane = other_lane.copy()
        self.cut_in = np.zeros(other_lane.shape, bool)

    def update(self, ego_y, ego_w, lane_w, gap, behind, v_ego, v_other, other_lane):
        """One sample: ``ego_y``, ``ego_w``, ``lane_w``, ``v_ego`` ``(B,)``; ``gap``, ``behind``, ``v_other``,
        ``other_lane`` ``(B, V)`` at that instant."""
        lanes = np.array(LANE_OFFSETS)
        now = body_in_lane(ego_y[:, None], ego_w[:, None], lanes[None, :], lane_w[:, None])
        entered = now & ~self.inside
        if entered.any():
            ok = ~behind | (gap >= np.maximum(rear_safe_distance(v_ego[:, None], v_other), self.margin_m))
            self.clean = np.where(entered[:, :, None], ok[:, None, :], self.clean)
            self.cut_in &= ~self._of_lane(entered, other_lane)
        moved = (other_lane != self.lane) & (other_lane != NO_LANE) & (self.lane != NO_LANE)
        if moved.any():
            safe = np.where(
                behind, rear_safe_distance(v_ego[:, None], v_other), ego_safe_distance(v_other, v_ego[:, None])
            )
            safe = np.maximum(safe, self.margin_m)
            ego_there = self._of_lane(now, other_lane)
            self.cut_in = np.where(moved, ego_there & (gap < safe), self.cut_in)
        self.lane = np.where(other_lane != NO_LANE, other_lane, self.lane)
        self.inside = now

    @staticmethod
    def _of_lane(per_lane, lane):
        """``per_lane (B, 4)`` looked up at each vehicle's lane ``(B, V)`` (``False`` outside :data:`LANE_OFFSETS`)."""
        idx = np.clip(lane - LANE_OFFSETS[0], 0, len(LANE_OFFSETS) - 1)
        known = (lane >= LANE_OFFSETS[0]) & (lane <= LANE_OFFSETS[-1])
        return known & np.take_along_axis(per_lane, idx, 1)

    def clean_for(self, lane):
        """``(B, V)``: the ego's entry into each vehicle's lane ``lane`` ``(B, V)`` was clean (``False`` for a lane
        outside :data:`LANE_OFFSETS`)."""
        idx = np.clip(lane - LANE_OFFSETS[0], 0, len(LANE_OFFSETS) - 1)
        known = (lane >= LANE_OFFSETS[0]) & (lane <= LANE_OFFSETS[-1])
        return known & np.take_along_axis(self.clean, idx[:, None, :], 1)[:, 0, :]


def blame_other(behind, in_lane, clean, cut_in):
    """The blame rule (module docstring): the replayed vehicle's fault iff the ego's body is in its lane and either it
    is behind the ego and the ego's entry into that lane was clean, or it cut in; all ``(B, V)``."""
    return in_lane & ((behind & clean) | cut_in)


class Referee:
    """The running outcome of every event, sample by sample: the first contact with each replayed vehicle (a
    continuing overlap is one collision; after it, nothing more of that pair counts, as a non-reactive replay drives
    on through the ego) and the first ``p_m`` violation, each blamed by :func:`blame_other`.

    A ``p_m`` violation is a replayed vehicle in a lane the ego's body takes whose bumper-to-bumper gap is below
    ``margin_m``; a pair that already breaks it at the start is the recording's (``inherited``) until it clears.
    """

    def __init__(self, n: int, inherited):
        self.touching = np.zeros_like(inherited)
        self.inherited = inherited.copy()
        self.pm_inherited = inherited.any(1)
        self.collision_t, self.pm_t = np.full(n, np.nan), np.full(n, np.nan)
        self.collision_with, self.pm_with = np.full(n, -1, np.int64), np.full(n, -1, np.int64)
        self.collision_blame, self.pm_blame = np.full(n, "", object), np.full(n, "", object)
        for name in ("collision_ego", "collision_other", "pm_ego", "pm_other"):
            setattr(self, name, np.zeros(n, bool))

    def sample(self, t, hits, breaks, other):
        """One instant ``t``: ``hits`` (overlapping footprints), ``breaks`` (gap below the margin), ``other`` (the
        blame rule says the vehicle's fault), all ``(B, V)``."""
        rows = np.arange(len(hits))
        contact = hits & ~self.touching
        # After a contact a replayed vehicle drives on through the ego (it does not react): what that pair does
        # next is not counted again.
        breaks = breaks & ~self.touching
        self.touching |= hits
        self.collision_ego |= (contact & ~other).any(1)
        self.collision_other |= (contact & other).any(1)
        first = contact.any(1) & np.isnan(self.collision_t)
        who = np.argmax(contact, 1)
        self.collision_t[first], self.collision_with[first] = t, who[first]
        self.collision_blame[first] = np.where(other[rows, who], "other", "ego")[first]
        self.inherited &= breaks
        fresh = breaks & ~self.inherited
        self.pm_ego |= (fresh & ~other).any(1)
        self.pm_other |= (fresh & other).any(1)
        first = fresh.any(1) & np.isnan(self.pm_t)
        who = np.argmax(fresh, 1)
        self.pm_t[first], self.pm_with[first] = t, who[first]
        self.pm_blame[first] = np.where(other[rows, who], "other", "ego")[first]

    def columns(self) -> dict:
        names = (
            "collision_t",
            "collision_with",
            "collision_blame",
            "collision_ego",
            "collision_other",
            "pm_t",
            "pm_with",
            "pm_blame",
            "pm_ego",
            "pm_other",
            "pm_inherited",
        )
        out = {name: getattr(self, name) for name in names}
        out["collision"] = self.collision_ego | self.collision_other
        return out
