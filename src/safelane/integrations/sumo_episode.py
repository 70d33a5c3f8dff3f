"""What a SUMO episode takes and gives (:mod:`safelane.integrations.sumo`): the scenario of one lane change
(:class:`SumoScenario`, built from the built-in simulator's sampler) and its outcome (:class:`EpisodeResult`: SUMO's
collision list as the referee, our geometric cross-check, what the shield did), in the built-in simulator's table
layout. Pure data: nothing here needs libsumo.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..shield.monitor import BREACH_KINDS


@dataclass(frozen=True)
class SumoScenario:
    """One lane change (shield frame: ``x`` along the road, the ego's centre at ``ego_x``; lanes by index).

    Target lane: F at ``f_x`` and ``L1..L(N+1)`` at ``leaders_x`` (centres, increasing), ``L1..LN`` connected with
    promise ``promise_decel``; ``L(N+1)`` brakes at ``decel_last`` from ``brake_start_s`` until it stops. Own lane:
    ``L0`` at ``own_x`` (``None``: none), braking at ``own_decel`` from ``own_brake_start_s`` (not connected)."""

    ego_x: float
    ego_v: float
    f_x: float
    f_v: float
    leaders_x: tuple[float, ...]
    leaders_v: tuple[float, ...]
    n_connected: int
    decel_last: float
    f_connected: bool = True
    f_aggressive: bool = False
    promise_decel: float = 0.5
    promise_accel: float = 0.5
    brake_start_s: float = 0.0
    own_x: float | None = None
    own_v: float = 30.0
    own_decel: float = 0.0
    own_brake_start_s: float = 0.0
    scenario_id: int = 0

    def __post_init__(self):
        if len(self.leaders_x) != len(self.leaders_v) or not self.leaders_x:
            raise ValueError("leaders_x and leaders_v must hold the same number (>= 1) of leaders")
        if not 0 <= self.n_connected <= len(self.leaders_x) - 1:
            raise ValueError(f"n_connected must lie in [0, {len(self.leaders_x) - 1}]; got {self.n_connected}")
        if np.any(np.diff(self.leaders_x) <= 0) or self.f_x >= self.leaders_x[0]:
            raise ValueError("leaders must be ordered along the road, F behind L1")
        if self.own_x is not None and self.own_x <= self.ego_x:
            raise ValueError("L0 must be ahead of the ego")


def scenarios_from_batch(batch, *, brake_start_s: float = 0.0) -> list[SumoScenario]:
    """The rows of a :class:`safelane.sim.ScenarioBatch` (e.g. ``paper_scenarios``) as SUMO scenarios (a straight
    ego start, ``y = 0``; the lateral start of the batch is not used)."""
    out = []
    for b in range(len(batch.ego_x)):
        k = int(batch.n_connected[b]) + 2
        out.append(SumoScenario(
            ego_x=float(batch.ego_x[b]), ego_v=float(batch.ego_vx[b]), f_x=float(batch.x[b, 0]),
            f_v=float(batch.v[b, 0]), leaders_x=tuple(batch.x[b, 1:k].tolist()),
            leaders_v=tuple(batch.v[b, 1:k].tolist()), n_connected=int(batch.n_connected[b]),
            decel_last=float(batch.decel_last[b]), f_connected=bool(batch.connected[b, 0]),
            f_aggressive=bool(batch.follower_aggressive[b]), promise_decel=float(batch.promise_decel[b, 1]),
            promise_accel=float(batch.promise_accel[b, 1]), brake_start_s=brake_start_s,
            scenario_id=int(batch.scenario_id[b]),
        ))  # fmt: skip
    return out


def sumo_scenarios(
    n_leaders: int,
    decel: float,
    samples: int,
    seed: int = 0,
    *,
    own_share: float = 0.0,
    own_gap: tuple[float, float] = (25.0, 45.0),
    own_decel: tuple[float, float] = (0.0, 8.0),
    own_brake_start_s: tuple[float, float] = (0.0, 3.0),
    first_id: int = 0,
) -> list[SumoScenario]:
    """The paper's sampler (``safelane.sim.paper_scenarios``, variant CV_all) and, in a share ``own_share`` of them,
    an ``L0`` in the ego's lane ``U[own_gap]`` m ahead at the traffic's speed that brakes at ``U[own_decel]`` from
    ``U[own_brake_start_s]``."""
    from ..sim.scenario import paper_scenarios

    rng = np.random.default_rng(seed)
    batch = paper_scenarios("CV_all", n_leaders, decel, samples, rng, first_id=first_id)
    out = scenarios_from_batch(batch)
    own = rng.uniform(size=samples) < own_share
    gap, a0, t0 = (rng.uniform(*r, size=samples) for r in (own_gap, own_decel, own_brake_start_s))
    for i in np.flatnonzero(own):
        out[i] = dataclasses.replace(out[i], own_x=out[i].ego_x + float(gap[i]), own_v=float(batch.v[i, 1]),
                                     own_decel=float(a0[i]), own_brake_start_s=float(t0[i]))  # fmt: skip
    return out


@dataclass
class EpisodeResult:
    """One episode: what happened by SUMO's list (``collided``, ``collisions``), our geometric cross-check
    (``overlaps``), and what the shield did."""

    scenario_id: int
    n_leaders: int
    decel: float
    has_l0: bool
    own_decel: float
    traffic: str
    shielded: bool
    steps: int = 0
    completed: bool = False
    collided: bool = False
    collisions: list = field(default_factory=list)
    overlaps: list = field(default_factory=list)
    n_proceed: int = 0
    n_hesitate: int = 0
    n_abort: int = 0
    n_invalid: int = 0
    completion_time_s: float = np.nan
    initial_safe: bool = False
    f_aggressive: bool = False
    f_connected: bool = True
    assessed_aggressive: bool = True
    assessment_time_s: float = np.nan
    breach: bool = False
    breach_time_s: float = np.nan
    breach_flags: tuple = ()
    promise_violations: int = 0
    v2x_sent: int = 0
    v2x_lost: int = 0
    wall_s: float = 0.0

    @property
    def success(self) -> bool:
        return self.completed and not self.collided

    def row(self) -> dict:
        first = self.collisions[0] if self.collisions else {}
        return {
            "scenario_id": self.scenario_id, "n_leaders": self.n_leaders, "decel": self.decel, "has_l0": self.has_l0,
            "own_decel": self.own_decel, "traffic": self.traffic, "shielded": self.shielded, "steps": self.steps,
            "completed": self.completed, "success": self.success, "collided": self.collided,
            "collider": first.get("collider", ""), "victim": first.get("victim", ""), "lane": first.get("lane", ""),
            "phase": first.get("phase", ""), "t_collision_s": first.get("t", np.nan),
            "geometric_overlap": bool(self.overlaps), "n_hesitate": self.n_hesitate, "n_abort": self.n_abort,
            "breach": self.breach, "promise_violations": self.promise_violations, "wall_s": self.wall_s,
        }  # fmt: skip

    def results_row(self, planner: str) -> dict:
        """The row in the built-in simulator's results table layout (``safelane.sim.results.results_table``), for
        the columns that apply: ``collision`` is the ego in SUMO's list, ``leader_collision`` a pair without the
        ego; then SUMO's own columns."""
        ego_hit = [c for c in self.collisions if "ego" in (c.get("collider"), c.get("victim"))]
        others = [c for c in self.collisions if "ego" not in (c.get("collider"), c.get("victim"))]
        first = self.collisions[0] if self.collisions else {}
        flags = dict(zip(BREACH_KINDS, self.breach_flags or (False,) * len(BREACH_KINDS), strict=True))
        return {
            "scenario_id": self.scenario_id, "planner": planner, "n_leaders": self.n_leaders, "decel": self.decel,
            "p_v": 0.0, "success": self.completed and not ego_hit, "collision": bool(ego_hit),
            "leader_collision": bool(others), "completed": self.completed,
            "completion_time_s": self.completion_time_s, "n_proceed": self.n_proceed, "n_hesitate": self.n_hesitate,
            "n_abort": self.n_abort, "follower_connected": self.f_connected, "follower_aggressive": self.f_aggressive,
            "assessed_aggressive": self.assessed_aggressive,
            "assessment_correct": self.assessed_aggressive == self.f_aggressive,
            "assessment_time_s": self.assessment_time_s, "n_invalid_proposals": self.n_invalid,
            "assumption_breach": self.breach, "breach_time_s": self.breach_time_s,
            **{f"breach_{kind}": flag for kind, flag in flags.items()}, "initial_safe": self.initial_safe,
            "traffic": self.traffic, "shielded": self.shielded, "has_l0": self.has_l0, "steps": self.steps,
            "sumo_collisions": len(self.collisions), "collider": first.get("collider", ""),
            "victim": first.get("victim", ""), "lane": first.get("lane", ""), "phase": first.get("phase", ""),
            "t_collision_s": first.get("t", np.nan), "geometric_overlap": bool(self.overlaps),
            "promise_violations": self.promise_violations, "v2x_sent": self.v2x_sent, "v2x_lost": self.v2x_lost,
            "wall_s": self.wall_s,
        }  # fmt: skip
