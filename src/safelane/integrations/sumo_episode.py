"""What a SUMO episode takes and gives (:mod:`safelane.integrations.sumo`): the scenario of one lane change
(:class:`SumoScenario`, built from the built-in simulator's sampler) and its outcome (:class:`EpisodeResult`: SUMO's
collision list as the referee, our geometric cross-check, what the shield did, who is responsible for each collision:
:class:`StateLog`), in the built-in simulator's table layout. Pure data: nothing here needs libsumo.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..baselines.rss import RssParams
from ..blame import Track, blame
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


class StateLog:
    """Every vehicle's state at every step of an episode, and the blame rule (:mod:`safelane.blame`) on SUMO's
    collision list from it: each entry gets ``blame`` (``"collider"``, ``"victim"`` or ``"both"``), ``responsible``
    (that vehicle's id, or ``"both"``), ``blame_clause`` and ``blame_t``. SUMO gives a vehicle's speed along its lane
    but not its lateral speed: lateral speeds are differenced from consecutive positions (0 at the first sample),
    except where the runner knows them (the ego's, exact)."""

    def __init__(self, ids, length: float, width: float, rss: RssParams):
        self.ids, self.length, self.width, self.rss = list(ids), float(length), float(width), rss
        self.t: list[float] = []
        self.rows: list[np.ndarray] = []  # per sample: (4, n) x, y, vx, vy

    def record(self, t: float, x, y, vx, vy=None) -> None:
        """One sample (arrays in ``ids`` order); ``vy``: NaN where unknown (then differenced)."""
        x, y, vx = (np.asarray(q, float) for q in (x, y, vx))
        diff = (y - self.rows[-1][1]) / (t - self.t[-1]) if self.rows else np.zeros_like(y)
        vy = diff if vy is None else np.where(np.isnan(np.asarray(vy, float)), diff, np.asarray(vy, float))
        self.t.append(float(t))
        self.rows.append(np.stack([x, y, vx, vy]))

    def classify(self, collisions: list[dict]) -> None:
        """Add the rule's verdict to each of SUMO's collision entries (``collider``, ``victim``, ``t``) in place,
        all entries in one batch."""
        known = [c for c in collisions if c.get("collider") in self.ids and c.get("victim") in self.ids]
        if not known or not self.rows:
            return
        data = np.stack(self.rows, -1)  # (4, n, T)
        # The ego's slot is the ego where it takes part (so "ego" reads as the ego), else the collider.
        first = [c["victim"] if c["victim"] == "ego" else c["collider"] for c in known]
        second = [c["collider"] if c["victim"] == "ego" else c["victim"] for c in known]
        a, b = (np.array([self.ids.index(v) for v in who]) for who in (first, second))
        track = lambda i: Track(*data[:, i], self.length, self.width)  # noqa: E731
        out = blame(np.array(self.t), track(a), track(b), np.array([c["t"] for c in known], float), self.rss)
        for c, f, s, who, clause, t_b in zip(known, first, second, out.labels(), out.clause_names(), out.blame_t,
                                             strict=True):  # fmt: skip
            responsible = {"ego": f, "other": s, "both": "both"}.get(who, "")
            role = "both" if who == "both" else ("collider" if responsible == c["collider"] else "victim")
            c.update(blame=role if who else "", responsible=responsible, blame_clause=clause,
                     blame_t=round(float(t_b), 3) if np.isfinite(t_b) else np.nan)  # fmt: skip


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

    @property
    def collision_blame(self) -> str:
        """Who is responsible for the ego's first collision by the blame rule (:class:`StateLog`): ``"ego"``,
        ``"other"``, ``"both"``, or ``""`` without one."""
        for c in self.collisions:
            if "ego" in (c.get("collider"), c.get("victim")) and c.get("responsible"):
                return {"ego": "ego", "both": "both"}.get(c["responsible"], "other")
        return ""

    def row(self) -> dict:
        first = self.collisions[0] if self.collisions else {}
        return {
            "scenario_id": self.scenario_id, "n_leaders": self.n_leaders, "decel": self.decel, "has_l0": self.has_l0,
            "own_decel": self.own_decel, "traffic": self.traffic, "shielded": self.shielded, "steps": self.steps,
            "completed": self.completed, "success": self.success, "collided": self.collided,
            "collider": first.get("collider", ""), "victim": first.get("victim", ""), "lane": first.get("lane", ""),
            "phase": first.get("phase", ""), "t_collision_s": first.get("t", np.nan),
            "collision_blame": self.collision_blame, "collision_blame_clause": self._first_ego("blame_clause"),
            "geometric_overlap": bool(self.overlaps), "n_hesitate": self.n_hesitate, "n_abort": self.n_abort,
            "breach": self.breach, "promise_violations": self.promise_violations, "wall_s": self.wall_s,
        }  # fmt: skip

    def _first_ego(self, key: str):
        hits = [c for c in self.collisions if "ego" in (c.get("collider"), c.get("victim"))]
        return hits[0].get(key, "") if hits else ""

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
            "collision_blame": self.collision_blame, "collision_blame_clause": self._first_ego("blame_clause"),
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
