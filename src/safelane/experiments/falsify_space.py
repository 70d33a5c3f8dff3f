"""The falsifier's search space: scenario specs inside the paper's assumptions, and how they become a batch.

A **spec** is a dict of NumPy arrays with one row per scenario — the physical values that define it (speeds, gaps,
the L(N+1) profile, the adversarial planner's and the traffic hooks' parameters). Specs come from three places:

* :func:`decode` maps a point ``u ∈ [0, 1]^D`` of the unit cube (random search, cross-entropy) to a spec. Each
  coordinate has an *edge mixture*: part of its range maps to exact edge values (a slack of exactly 0, a speed
  equal to the vehicle ahead's, the others' maximum braking ``a_o_d`` exactly), part to tiny values (log-uniform
  down to 1e-12), the rest to the plain range. The others brake up to their own maximum ``Params.others_decel``
  (``a_o_d``; ``a_x_d`` in the paper's world), not only up to the ego's committed ``a_x_d``;
* :func:`knife_specs` snaps random specs to knife edges: leaders exactly at their margin at equal speed, speed
  matches that land on a period boundary, profile switches on or a hair off a boundary, lateral positions at the
  conflict-zone edge and the lane boundary;
* a JSON dump of one row (replay).

:mod:`safelane.experiments.falsify_build` turns a spec into a batch, the adversarial nominal planner and the traffic
hooks, and says which rows satisfy the assumptions at ``t = 0``.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..planners.variants import PAPER_VARIANT_NAMES, VARIANT_NAMES

MAX_N = 10  #: most connected leaders searched
L = MAX_N + 1  #: leader slots L1..L(N+1)
P = 4  #: segments of L(N+1)'s acceleration profile
MAX_OWN = 3  #: most connected own-lane vehicles searched (L0 and the ones ahead of it; the realistic world)
PLANNER_PARAMS = 12


class _Cube:
    """Reads consecutive columns of ``u``; ``width`` counts them (``decode`` on a probe gives ``D``)."""

    def __init__(self, u: np.ndarray):
        self.u, self.width = u, 0

    def take(self, w: int = 1) -> np.ndarray:
        c = self.u[:, self.width : self.width + w]
        self.width += w
        return c[:, 0] if w == 1 else c


def lin(u, lo, hi):
    return lo + (hi - lo) * u


def _edge(u, lo, hi, *, exact=None, p_exact=0.1, p_tiny=0.2, tiny_lo=1e-12):
    """Edge mixture on ``[lo, hi]``: ``u < p_exact`` → ``exact`` (default ``lo``); the next ``p_tiny`` → ``lo``
    plus a log-uniform tiny amount in ``[tiny_lo, 1]``; the rest uniform on ``[lo, hi]``."""
    exact = lo if exact is None else exact
    tiny = lo + np.exp(lin(np.clip((u - p_exact) / max(p_tiny, 1e-300), 0, 1), np.log(tiny_lo), 0.0))
    plain = lin(np.clip((u - p_exact - p_tiny) / (1 - p_exact - p_tiny), 0, 1), lo, hi)
    return np.where(u < p_exact, exact, np.where(u < p_exact + p_tiny, tiny, plain))


#: The worlds the falsifier searches: the paper's, and the realistic one (docs/real_roads.md: an own-lane leader L0
#: with a braking profile, measurement errors inside their bounds, actuation delay 0–0.3 s), whose extra coordinates
#: come after the paper's (the paper's decode is unchanged).
WORLDS = ("paper", "realistic")
MAX_DELAY_PERIODS = 3


def decode(u: np.ndarray, prm: Params, brake_start_s: float = 0.0, world: str = "paper") -> dict[str, np.ndarray]:
    """The spec of each row of ``u`` (``(n, D)`` in ``[0, 1]``); see the module docstring."""
    u = np.clip(np.asarray(u, float), 0.0, 1.0)
    c = _Cube(u)
    n = np.minimum((c.take() * (MAX_N + 1)).astype(np.int64), MAX_N)
    spec = {"n": n}
    # The paper's variants only (the RSS baselines make no guarantee; their indices follow the paper's).
    spec["variant"] = np.minimum((c.take() * len(PAPER_VARIANT_NAMES)).astype(np.int64), len(PAPER_VARIANT_NAMES) - 1)
    spec["ego_y"] = np.where(c.take() < 0.4, 0.0, lin(c.take(), 0.0, prm.lane_width))
    spec["ego_vy"] = np.where(c.take() < 0.4, 0.0, lin(c.take(), -2.0, 2.0))
    spec["ego_dv"] = np.where(c.take() < 0.2, 0.0, lin(c.take(), -10.0, 10.0))  # ego speed − L1's
    spec["l1_slack"] = _edge(c.take(), 0.0, 40.0)  # L1 − ego − p_m
    spec["f_slack"] = _edge(c.take(), 0.0, 40.0)  # ego − F − p_m
    spec["f_dv"] = np.where(c.take() < 0.2, 0.0, lin(c.take(), -10.0, 10.0))  # F's speed − the ego's
    f_type = c.take()
    spec["f_connected"] = f_type < 1 / 3
    spec["f_aggressive"] = f_type >= 2 / 3
    spec["base_v"] = _edge(c.take(), 0.0, 40.0, exact=30.0)  # L(N+1)'s speed
    spec["lv_dv"] = np.where(c.take(L) < 0.3, 0.0, lin(c.take(L), -8.0, 8.0))  # L_i − L(i+1) speed
    spec["slack"] = _edge(c.take(L), 0.0, 40.0)  # L(i+1) − L_i − margin_i
    spec["human"] = c.take(L) < 0.2
    spec["promise_decel"] = _edge(c.take(L), 0.0, prm.others_decel, exact=0.5, p_exact=0.3, p_tiny=0.1)
    spec["promise_accel"] = _edge(c.take(L), 0.0, prm.a_x_a, exact=0.5, p_exact=0.3, p_tiny=0.1)
    # L(N+1): piecewise-constant profile; segment j starts dt..3 s after j−1 (snapped to a period with prob 0.5).
    gaps = lin(c.take(P - 1), prm.dt, 3.0)
    snap = c.take(P - 1) < 0.5
    gaps = np.where(snap, np.maximum(np.round(gaps / prm.dt), 1.0) * prm.dt, gaps)
    spec["profile_t"] = np.concatenate([np.zeros((len(u), 1)), np.cumsum(gaps, axis=1)], axis=1)
    acc = lin(c.take(P), -prm.others_decel, prm.a_x_a)  # the others brake up to their own maximum a_o_d
    spec["profile_a"] = np.where(c.take(P) < 0.25, -prm.others_decel, acc)
    spec["decel_last"] = _edge(c.take(), 1e-3, prm.others_decel, exact=prm.others_decel, p_exact=0.3, p_tiny=0.0)
    spec["brake_start_s"] = np.full(len(u), float(brake_start_s))
    spec["mode"] = np.minimum((c.take() * 4).astype(np.int64), 3)
    spec["planner"] = c.take(PLANNER_PARAMS)
    spec["task_hi"] = c.take(L)  # leaders' own tasks: a square wave between two levels inside the promise
    spec["task_lo"] = c.take(L)
    spec["task_period_s"] = lin(c.take(), prm.dt, 4.0)
    spec["task_phase"] = c.take()
    spec["f_hi"] = c.take()  # F's wish: a square wave between two levels inside [−a_x_d, a_x_a]
    spec["f_lo"] = c.take()
    spec["f_period_s"] = lin(c.take(), prm.dt, 4.0)
    spec["f_phase"] = c.take()
    if world == "realistic":
        _decode_realistic(c, spec, prm)
    spec["_width"] = np.full(len(u), c.width)
    return spec


def _decode_realistic(c: _Cube, spec: dict, prm: Params) -> None:
    """L0 (present in 85 % of rows): its slack behind which the ego starts (edge mixture: exactly ``p_m``), its speed
    relative to the ego's, a piecewise-constant profile as L(N+1)'s (a quarter of the segments at ``-a_o_d``); the
    actuation delay in periods (0–3); the own lane as a chain (half the rows with L0): up to :data:`MAX_OWN`
    connected vehicles from L0 on, each a slack (edge mixture: exactly ``p_m``) ahead of the one behind it, a speed
    relative to it, a promise in ``[0, a_x_d]`` and an instant from which it brakes at it (a fifth never), the
    vehicle ahead of them driving L0's profile."""
    n = len(spec["n"])
    spec["l0_present"] = c.take() < 0.85
    spec["l0_slack"] = _edge(c.take(), 0.0, 60.0)  # L0 − ego − p_m
    spec["l0_dv"] = np.where(c.take() < 0.3, 0.0, lin(c.take(), -5.0, 10.0))  # L0's speed − the ego's
    gaps = lin(c.take(P - 1), prm.dt, 3.0)
    snap = c.take(P - 1) < 0.5
    gaps = np.where(snap, np.maximum(np.round(gaps / prm.dt), 1.0) * prm.dt, gaps)
    spec["l0_profile_t"] = np.concatenate([np.zeros((n, 1)), np.cumsum(gaps, axis=1)], axis=1)
    acc = lin(c.take(P), -prm.others_decel, prm.a_x_a)
    spec["l0_profile_a"] = np.where(c.take(P) < 0.25, -prm.others_decel, acc)
    spec["delay_periods"] = np.minimum((c.take() * (MAX_DELAY_PERIODS + 1)).astype(np.int64), MAX_DELAY_PERIODS)
    spec["world_key"] = (c.take() * 2**52).astype(np.int64)  # keys the measurement errors: a replay draws the same
    u_n = c.take()
    spec["own_n"] = np.where(spec["l0_present"] & (u_n >= 0.5), 1 + np.minimum(((u_n - 0.5) * 2 * MAX_OWN).astype(
        np.int64), MAX_OWN - 1), 0)  # fmt: skip
    spec["own_slack"] = _edge(c.take(MAX_OWN), 0.0, 40.0)  # each one − the one behind it − p_m
    spec["own_dv"] = np.where(c.take(MAX_OWN) < 0.3, 0.0, lin(c.take(MAX_OWN), -3.0, 6.0))
    spec["own_promise"] = _edge(c.take(MAX_OWN), 0.0, prm.a_x_d, exact=prm.a_x_d, p_exact=0.1, p_tiny=0.1)
    spec["own_brake_t"] = np.where(c.take(MAX_OWN) < 0.2, np.inf, lin(c.take(MAX_OWN), 0.0, 6.0))


def dimension(prm: Params, world: str = "paper") -> int:
    """``D``, the number of coordinates :func:`decode` reads."""
    return int(decode(np.zeros((1, 1000)), prm, world=world)["_width"][0])


def take(spec: dict, rows) -> dict:
    """Rows ``rows`` of a spec."""
    return {k: v[rows] for k, v in spec.items()}


def concat_specs(specs: list[dict]) -> dict:
    return {k: np.concatenate([s[k] for s in specs]) for k in specs[0]}


def knife_specs(rng: np.random.Generator, count: int, prm: Params, brake_start_s: float = 0.0,
                world: str = "paper") -> dict:  # fmt: skip
    """Random specs snapped to knife edges (each edge applied to a random share of the rows):

    * **margin ties**: leaders exactly at their margin behind the vehicle ahead at the same speed (the state the
      chain's own worst-case trajectory ends in); the ego exactly at ``p_m`` behind L1 at L1's speed; F exactly at
      ``p_m`` behind the ego. Positions are multiples of 1/1024 m, so the slacks are exactly 0 in floating point;
    * **speed matches on a period boundary**: L(N+1) slower than L_N by ``a·k·dt``, accelerating at ``a`` for
      exactly ``k`` periods (then constant), with the slack that makes the gap exactly the margin at the match;
    * **period-aligned events**: profile switches at ``k·dt`` (computed as ``k·dt`` and as a running sum of
      ``dt``, which differ in the last bit) or a hair off it (±1e-12, ±1e-9 s) or mid-period; brake, ease off,
      brake harder; planner and traffic square waves with periods that are multiples of ``dt``, phase 0;
    * **lateral edges**: the ego at ``y_s`` or the lane boundary (± one ulp, ± 1e-12), lateral speed 0 or tiny;
    * **the paper's setting with a hugging planner** (where the guarantee's first hole showed): traffic at 30 m/s, one
      spacing ``δp ~ U[17, 22]`` m, promises 0.5, L(N+1) braking at one constant deceleration, CV_all, hug L1.
    """
    spec = decode(rng.uniform(size=(count, dimension(prm, world))), prm, brake_start_s, world)
    n = spec["n"]
    pick = lambda p: rng.uniform(size=count) < p  # noqa: E731
    # Margin ties among the leaders (and speed ties), ego behind L1, F behind the ego.
    tie_links = rng.uniform(size=(count, L)) < 0.5
    spec["slack"] = np.where(tie_links, 0.0, np.round(spec["slack"] * 1024) / 1024)
    spec["lv_dv"] = np.where(tie_links | pick(0.5)[:, None], 0.0, spec["lv_dv"])
    spec["base_v"] = np.round(spec["base_v"] * 64) / 64
    ego_tie = pick(0.5)
    spec["l1_slack"] = np.where(ego_tie, 0.0, np.round(spec["l1_slack"] * 1024) / 1024)
    spec["ego_dv"] = np.where(ego_tie | pick(0.3), 0.0, spec["ego_dv"])
    f_tie = pick(0.3)
    spec["f_slack"] = np.where(f_tie, 0.0, spec["f_slack"])
    spec["f_dv"] = np.where(f_tie, 0.0, spec["f_dv"])
    # Speed match on a period boundary between L_N and L(N+1): L(N+1) accelerates at a for k periods.
    match = pick(0.3)
    k = rng.integers(1, 30, size=count)
    a = rng.choice([0.5, 1.0, prm.a_x_a], size=count)
    closing = a * k * prm.dt
    t_match = np.where(pick(0.5), k * prm.dt, np.array([sum([prm.dt] * int(j)) for j in k]))
    spec["base_v"] = np.where(match, np.maximum(spec["base_v"], closing), spec["base_v"])
    rows = np.flatnonzero(match)
    spec["lv_dv"][rows, n[rows] - 1] = np.where(n[rows] >= 1, closing[rows], spec["lv_dv"][rows, n[rows] - 1])
    spec["slack"][rows, n[rows] - 1] = np.where(
        n[rows] >= 1, 0.5 * a[rows] * t_match[rows] ** 2, spec["slack"][rows, n[rows] - 1]
    )
    # Period-aligned L(N+1) profiles: brake, ease off, brake harder (or the match above, then constant).
    starts = np.cumsum(rng.integers(1, 25, size=(count, P - 1)), axis=1)
    running = np.array([[sum([prm.dt] * int(s)) for s in row] for row in starts])
    aligned = np.where(pick(0.5)[:, None], starts * prm.dt, running)
    jitter = rng.choice([0.0, 0.0, 1e-12, -1e-12, 1e-9, -1e-9, 0.5 * prm.dt], size=(count, P - 1))
    times = np.concatenate([np.zeros((count, 1)), aligned + jitter], axis=1)
    d1, d2 = rng.uniform(0.5, prm.others_decel, size=count), rng.uniform(0.0, 0.5, size=count)
    harder = np.stack([-d1, -d2 * d1, -prm.others_decel * np.ones(count), np.zeros(count)], 1)
    profile_a = np.where(pick(0.5)[:, None], harder, spec["profile_a"])
    hardest = -prm.others_decel * np.ones(rows.size)
    profile_a[rows] = np.stack([a[rows], np.zeros(rows.size), np.zeros(rows.size), hardest], 1)
    times[rows, 1] = t_match[rows]
    times[rows, 2:] = np.maximum(times[rows, 2:], t_match[rows, None] + prm.dt * np.arange(1, P - 1))
    for j in range(1, P):  # at most one switch per period: a jittered switch may not come within dt of the last
        times[:, j] = np.where(times[:, j] - times[:, j - 1] < prm.dt, times[:, j - 1] + prm.dt, times[:, j])
    spec["profile_t"], spec["profile_a"] = times, profile_a
    # Period-aligned planner and traffic square waves.
    aligned_rows = pick(0.5)
    spec["task_period_s"] = np.where(aligned_rows, 2 * prm.dt * rng.integers(1, 20, size=count), spec["task_period_s"])
    spec["task_phase"] = np.where(aligned_rows, 0.0, spec["task_phase"])
    spec["f_period_s"] = np.where(aligned_rows, 2 * prm.dt * rng.integers(1, 20, size=count), spec["f_period_s"])
    osc_period = (rng.integers(1, 30, size=count) - 1) * prm.dt / 2.9  # planner_for: period dt + 2.9·q
    spec["planner"][:, 5] = np.where(aligned_rows, osc_period, spec["planner"][:, 5])
    spec["planner"][:, 6] = np.where(aligned_rows, 0.0, spec["planner"][:, 6])
    # The paper's own setting with a hugging planner (where the guarantee's first hole showed): traffic at 30 m/s,
    # one spacing δp ~ U[17, 22] m, promises 0.5, L(N+1) braking at one constant deceleration, CV_all, hug L1.
    paper = pick(0.2)
    rows = np.flatnonzero(paper)
    spacing = rng.uniform(17.0, 22.0, size=rows.size)[:, None] - prm.p_m
    spec["n"][rows] = rng.integers(1, MAX_N + 1, size=rows.size)
    spec["variant"][rows] = VARIANT_NAMES.index("CV_all")
    spec["mode"][rows] = 0
    spec["base_v"][rows], spec["lv_dv"][rows], spec["human"][rows] = 30.0, 0.0, False
    spec["slack"][rows] = spacing
    spec["l1_slack"][rows], spec["f_slack"][rows] = spacing[:, 0], spacing[:, 0]
    spec["ego_dv"][rows] = rng.uniform(-1.0, 1.0, size=rows.size)
    spec["f_dv"][rows] = -spec["ego_dv"][rows]
    spec["f_connected"][rows], spec["f_aggressive"][rows] = True, False
    spec["promise_decel"][rows], spec["promise_accel"][rows] = 0.5, 0.5
    spec["task_hi"][rows], spec["task_lo"][rows] = 0.5, 0.5  # wanted 0: hold the speed
    decel = rng.uniform(0.5, prm.a_x_d, size=rows.size)
    spec["decel_last"][rows] = decel
    spec["profile_a"][rows] = -decel[:, None]
    spec["planner"][rows, 2] = rng.uniform(0.2, 0.6, size=rows.size)  # offsets -0.001 … +0.33 m (planner_for)
    spec["ego_y"][rows], spec["ego_vy"][rows] = 0.0, 0.0
    # Lateral edges (not on the paper rows).
    y_edges = np.array(
        [
            prm.y_safe,
            np.nextafter(prm.y_safe, np.inf),
            prm.y_safe + 1e-12,
            prm.y_safe - 1e-12,
            prm.y_boundary,
            np.nextafter(prm.y_boundary, -np.inf),
            0.0,
        ]
    )
    lateral = pick(0.4) & ~paper
    spec["ego_y"] = np.where(lateral, rng.choice(y_edges, size=count), spec["ego_y"])
    spec["ego_vy"] = np.where(lateral, rng.choice([0.0, 1e-12, -1e-12, 0.5, -0.5], size=count), spec["ego_vy"])
    if world == "realistic":  # L0 at its margin at the ego's speed, braking at a_o_d from a period boundary or not
        tie = pick(0.5)
        spec["l0_slack"] = np.where(tie, 0.0, np.round(spec["l0_slack"] * 1024) / 1024)
        spec["l0_dv"] = np.where(tie | pick(0.3), 0.0, spec["l0_dv"])
        brake = pick(0.5)
        k0 = rng.integers(0, 30, size=count)
        t0 = np.where(pick(0.5), k0 * prm.dt, np.array([sum([prm.dt] * int(j)) for j in k0]))
        t0 = t0 + rng.choice([0.0, 0.0, 1e-12, 1e-9, 0.5 * prm.dt], size=count)
        times = np.stack([np.zeros(count), np.maximum(t0, prm.dt), np.maximum(t0, prm.dt) + 1.0,
                          np.maximum(t0, prm.dt) + 2.0], 1)  # fmt: skip
        accels = np.stack([rng.uniform(0.0, prm.a_x_a, count), -prm.others_decel * np.ones(count), np.zeros(count),
                           -prm.others_decel * np.ones(count)], 1)  # fmt: skip
        spec["l0_profile_t"] = np.where(brake[:, None], times, spec["l0_profile_t"])
        spec["l0_profile_a"] = np.where(brake[:, None], accels, spec["l0_profile_a"])
    return spec
