"""Traffic in the lanes beside the paper's two (``SimConfig.neighbours``): what the multi-lane world costs.

The paper's world has two lanes. On a real road there are vehicles in the lane beyond the target lane (lane 2) and
on the ego's other side (lane −1), and the shield's world model (docs/safety.md, "Other vehicles' lane changes")
cannot know that they will stay there: a non-connected vehicle beside the ego's lane counts in the ego's lane (rule
4), one beyond the target lane and ahead of the ego counts in the target lane (rule 5), each as a vehicle that may
enter at RSS's distance and brake. These vehicles *do* stay in their lanes here — at a constant speed, non-connected
— so the run measures the price of not knowing it (success, hesitation), never a collision they cause: the
simulator's checks do not change.

Per scenario and lane, a platoon: one speed, the ego's initial speed ``± neighbour_speed_spread_mps`` (uniform, at
least 1 m/s); time headways uniform in ``[neighbour_headway_min_s, neighbour_headway_max_s]`` between consecutive
vehicles (the bumper-to-bumper distance is the headway times the speed, plus a vehicle length between centres); the
first vehicle a uniform fraction of a headway ahead of :data:`BACK_M` behind the ego, the last one no farther than
:data:`FRONT_M` ahead of it. Every draw comes from counters ``(seed, scenario, slot)``, so a scenario's neighbours do
not depend on its batch, its chunk or the worker that runs it.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..shield.world import NO_LANE, Others
from .rng import counter_uniform

#: The lanes the neighbours drive in (the shield's frame: −1 the ego's other side, 2 beyond the target lane).
LANES = (-1, 2)
#: How far behind and ahead of the ego's initial position the platoons reach [m].
BACK_M, FRONT_M = 150.0, 250.0
#: Counter slot of the draws made here (kept apart from the other per-scenario draws).
_SLOT = 7300
#: The slowest lane speed drawn [m/s].
MIN_SPEED_MPS = 1.0


def slots(cfg, prm: Params) -> int:
    """Slots per lane: the most vehicles a platoon can hold (the shortest spacing at the slowest speed)."""
    spacing = MIN_SPEED_MPS * cfg.neighbour_headway_min_s + prm.vehicle_length
    return int(np.ceil((BACK_M + FRONT_M) / spacing)) + 1


class Neighbours:
    """The platoons of a batch: ``x0``, ``v`` ``(B, K)`` (``x0 = +inf``: no vehicle), ``y`` ``(K,)``."""

    def __init__(self, batch, seed: int, cfg, prm: Params):
        key = batch.scenario_id if batch.world_key is None else batch.world_key
        k = slots(cfg, prm)
        rows = len(key)
        xs, vs, ys = [], [], []
        for lane_i, lane in enumerate(LANES):
            base = _SLOT + 1000 * lane_i
            u_v = counter_uniform(seed, key, base)
            speed = np.maximum(batch.ego_vx + cfg.neighbour_speed_spread_mps * (2.0 * u_v - 1.0), MIN_SPEED_MPS)
            h_lo, h_hi = cfg.neighbour_headway_min_s, cfg.neighbour_headway_max_s
            n = np.arange(k)
            headway = h_lo + (h_hi - h_lo) * counter_uniform(seed, key[:, None], base + 1 + n[None, :])
            gaps = headway * speed[:, None] + prm.vehicle_length
            first = batch.ego_x - BACK_M + counter_uniform(seed, key, base + 999) * gaps[:, 0]
            x = first[:, None] + np.cumsum(gaps, axis=1) - gaps[:, :1]
            xs.append(np.where(x <= batch.ego_x[:, None] + FRONT_M, x, np.inf))
            vs.append(np.broadcast_to(speed[:, None], (rows, k)))
            ys.append(np.full(k, lane * prm.lane_width))
        self.x0, self.v, self.y = np.concatenate(xs, 1), np.concatenate(vs, 1), np.concatenate(ys)

    def at(self, t: float) -> Others:
        """The neighbours at time ``t`` as the shield's :class:`~safelane.shield.world.Others` (non-connected, no
        announcement, keeping their lanes)."""
        shape = self.x0.shape
        return Others(
            x=self.x0 + self.v * t, y=np.broadcast_to(self.y, shape).copy(), vx=self.v.copy(), vy=np.zeros(shape),
            connected=np.zeros(shape, bool), announce_lane=np.full(shape, NO_LANE), announce_t=np.full(shape, np.inf),
        )  # fmt: skip


__all__ = ["BACK_M", "FRONT_M", "LANES", "Neighbours", "slots"]
