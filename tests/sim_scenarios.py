"""Named scenario batches and motions for the simulator tests (and ``benchmarks/campaign_safety.py``).

Batches use :func:`safelane.sim.paper_scenarios` (F at ``−δp``, ``L_i`` at ``i·δp``, traffic at 30 m/s, ego at
``U[29, 31]`` m/s) and :func:`safelane.sim.concat`; motions use the default :class:`safelane.Params`
(``a_x_a = 2.5``, ``a_x_d = 8`` m/s², ``vehicle_length = 4.8``, ``p_m = 7`` m, ``dt = 0.1`` s).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from safelane.sim import ScenarioBatch, ScenarioConfig, concat, paper_scenarios
from safelane.sim.kinematics import Motion

#: The issue's safety campaign: these N, ``a_x_N+1_d ~ U[DECEL_RANGE]`` per scenario.
CAMPAIGN_LEADERS = (0, 1, 3, 5, 10)
DECEL_RANGE = (2.0, 8.0)

#: Mixed follower types: half connected (collaborative, says so over V2X); of the non-connected half, half
#: aggressive. Connected leaders are human-driven (larger margin ``p_m_human``) with probability 0.2.
MIXED_TRAFFIC = ScenarioConfig(follower_connected_share=0.5, follower_aggressive_share=0.5, human_share=0.2)


def mixed_campaign_batch(
    planner: str,
    samples: int,
    rng: np.random.Generator,
    *,
    p_v: float = 0.0,
    first_id: int = 0,
    leaders=CAMPAIGN_LEADERS,
    decel_range=DECEL_RANGE,
    config: ScenarioConfig = MIXED_TRAFFIC,
) -> ScenarioBatch:
    """``samples`` scenarios of ``planner`` spread evenly over ``leaders`` (N), each with its own sudden braking
    ``a_x_N+1_d ~ U[decel_range]`` and mixed follower types; scenario ids ``first_id, first_id + 1, …``."""
    parts = []
    counts = np.diff(np.linspace(0, samples, len(leaders) + 1).round().astype(int))
    next_id = first_id
    for n, count in zip(leaders, counts, strict=True):
        if count == 0:
            continue
        part = paper_scenarios(planner, n, decel_range[0], int(count), rng, config, first_id=next_id, p_v=p_v)
        decel = rng.uniform(*decel_range, size=int(count))
        parts.append(dataclasses.replace(part, decel_last=decel))
        next_id += int(count)
    return concat(parts)


def hardest_braking_chain(
    samples: int, rng: np.random.Generator, n_leaders: int = 10, planner: str = "CV_all"
) -> ScenarioBatch:
    """The hardest leader chains of the campaign: ``n_leaders`` connected leaders (some human-driven) behind an
    L(N+1) braking at 8 m/s² — the mechanical limit — from t = 0."""
    return paper_scenarios(planner, n_leaders, 8.0, samples, rng, MIXED_TRAFFIC)


# --- motions over one period -------------------------------------------------------------------------------------


def mid_period_contact(dt: float = 0.1, length: float = 4.8):
    """Two vehicles whose centre gap is ``length + 0.01`` m at both ends of the period but dips below
    ``length`` in the middle: the one behind brakes at 8 m/s² while closing at 0.525 m/s, the one ahead
    accelerates at 2.5 m/s² — relative acceleration 10.5 m/s², so the closing speed is zero at ``dt/2`` and
    the gap there is ``length + 0.01 − 10.5 dt²/8`` (4.796875 m for ``dt = 0.1``).

    Returns ``(behind, ahead)`` :class:`Motion` objects for a batch of one.
    """
    rel_acc = 2.5 + 8.0
    closing = rel_acc * dt / 2.0
    behind = Motion.constant(np.array([0.0]), np.array([30.0]), np.array([-8.0]), dt)
    ahead = Motion.constant(np.array([length + 0.01]), np.array([30.0 - closing]), np.array([2.5]), dt)
    return behind, ahead
