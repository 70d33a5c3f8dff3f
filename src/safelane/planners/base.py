"""The nominal-planner interface: ``(observation) -> (a_x, a_y)`` over a batch.

A nominal planner proposes accelerations; the safety supervisor (the shield, :mod:`safelane.shield`) decides
whether they are executed. Planners never see the true type of the follower or the worst case; they see
what the ego senses plus what V2X adds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, jitable

#: Names of the 8 state features of ASP-DAC'23, in order.
STATE_FEATURES = ("p_x", "p_y", "v_x", "v_y", "p_x_l", "v_x_l", "p_x_f", "v_x_f")


@dataclass(frozen=True)
class Observation:
    """What the ego knows at a control step; every array has the batch shape ``(B,)`` unless noted.

    Attributes:
        p_x, p_y, v_x, v_y: ego state (absolute; ``p_y`` from the original lane centre).
        p_x_l, v_x_l: ``L1`` position and speed (sensed).
        p_x_f, v_x_f: follower position and speed (sensed).
        l1_plan: ``(B, H)`` ``L1``'s planned accelerations over the next ``H`` control periods from its V2X
            message; zeros (constant-speed prediction) when ``L1`` is not connected or the variant ignores it.
        l1_connected, f_connected: whether that information came over V2X.
        completed: the lane change has completed (centre across the lane boundary).
        t: simulation time [s] (scalar).
        scenario_id: ``(B,)`` stable scenario ids where the caller has them (the simulator does): planners with
            per-scenario parameters index them by id, since a batch may be split over worker processes.
    """

    p_x: np.ndarray
    p_y: np.ndarray
    v_x: np.ndarray
    v_y: np.ndarray
    p_x_l: np.ndarray
    v_x_l: np.ndarray
    p_x_f: np.ndarray
    v_x_f: np.ndarray
    l1_plan: np.ndarray
    l1_connected: np.ndarray
    f_connected: np.ndarray
    completed: np.ndarray
    t: float = 0.0
    scenario_id: np.ndarray | None = None

    def state_matrix(self) -> np.ndarray:
        """The 8 ASP-DAC'23 features ``(B, 8)`` in :data:`STATE_FEATURES` order (absolute values)."""
        return np.stack([getattr(self, name) for name in STATE_FEATURES], axis=-1)


@runtime_checkable
class NominalPlanner(Protocol):
    """Anything callable as ``planner(obs, params) -> (a_x, a_y)`` on a batch."""

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]: ...


def clip_actions(a_x, a_y, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """``(a_x, a_y)`` clipped to the mechanical limits ``[−a_x_d, a_x_a]`` and ``[−a_y_m, a_y_m]``."""
    return (
        np.clip(np.asarray(a_x, float), -params.a_x_d, params.a_x_a),
        np.clip(np.asarray(a_y, float), -params.a_y_m, params.a_y_m),
    )


@dataclass(frozen=True)
class ExpertPlanner:
    """Rule-based teacher/baseline planner.

    Longitudinal: a PD law placing the ego in the F–L1 gap (at ``gap_fraction`` of the way from F to L1;
    0.5 is the middle) at L1's speed.
    Lateral: a critically damped PD law toward the target-lane centre ``y = w_l`` (natural frequency
    ``omega``), which gives a smooth lane change; both clipped to the mechanical limits.
    ``brake_comfort`` [m/s²]: the nominal planner never proposes braking harder than this (a comfort limit; the
    shield's abort still brakes at up to ``a_x_d``); the default (inf) is no limit.
    """

    k_p: float = 0.3
    k_v: float = 0.8
    omega: float = 0.65
    gap_fraction: float = 0.5
    brake_comfort: float = float("inf")

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(all="ignore"):
            return expert_accel(ARRAY, obs.p_x_f, obs.p_x_l, obs.v_x_l, obs.p_x, obs.p_y, obs.v_x, obs.v_y,
                                self.gains(), params.lane_width, params)  # fmt: skip

    def gains(self) -> ExpertGains:
        """The planner's gains as the closed form :func:`expert_accel` takes them."""
        return ExpertGains(self.k_p, self.k_v, self.gap_fraction, self.brake_comfort, self.omega**2, 2.0 * self.omega)


class ExpertGains(NamedTuple):
    """:class:`ExpertPlanner`'s gains (``omega2 = omega²``, ``two_omega = 2 omega``), a record the kernels take."""

    k_p: float
    k_v: float
    gap_fraction: float
    brake_comfort: float
    omega2: float
    two_omega: float


def expert_accel(xp, f_x, l1_x, l1_v, ego_x, ego_y, ego_vx, ego_vy, gains, lane_width, lim):
    """:class:`ExpertPlanner`'s proposal ``(a_x, a_y)``, backend-generic (the one source: the planner evaluates it on
    NumPy arrays, the compiled closed loop per row). ``gains``: :class:`ExpertGains`; ``lim``: ``Params`` or its
    ``Limits``: the proposal is clipped to the mechanical limits, as :func:`clip_actions`."""
    mid = f_x + gains.gap_fraction * (l1_x - f_x)
    a_x = xp.maximum(gains.k_p * (mid - ego_x) + gains.k_v * (l1_v - ego_vx), -gains.brake_comfort)
    a_y = gains.omega2 * (lane_width - ego_y) - gains.two_omega * ego_vy
    return xp.clip(a_x, -lim.a_x_d, lim.a_x_a), xp.clip(a_y, -lim.a_y_m, lim.a_y_m)


jitable(expert_accel)
