"""Settings of a simulation run (not of the scenario distribution): the world's, and the shield's as one
:class:`~safelane.shield.config.ShieldConfig` (``SimConfig.shield``) — the shield's settings have one home.

Presets and code written before the shield's settings moved still read: the flat keys of :data:`SHIELD_KEYS`
(``assessment``, ``supervised``, ``shield_own_lane``, …) go to ``shield`` under their names there, and
``shield_delay`` (whether the shield accounts for the world's actuation delay) sets ``shield.actuation_delay_s``.
Unless told otherwise the shield accounts for the world's delay: ``shield.actuation_delay_s`` defaults to
``actuation_delay_s``, and :meth:`SimConfig.model_copy` keeps it following a change of the world's delay where it
did before.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from ..shield.config import ShieldConfig

#: The flat keys that are the shield's settings, and their names in :class:`ShieldConfig`.
SHIELD_KEYS = {
    "assessment": "assessment", "assess_delay_s": "assess_delay_s", "assess_miss": "assess_miss",
    "completion": "completion", "assess_window": "assess_window", "assess_threshold": "assess_threshold",
    "monitor": "monitor", "supervised": "enabled", "shield_own_lane": "own_lane", "shield_sensing": "sensing",
}  # fmt: skip


class SimConfig(BaseModel):
    """Settings of a simulation run (not of the scenario distribution); the shield's in :attr:`shield`."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    shield: ShieldConfig = Field(
        default_factory=ShieldConfig,
        description="How the shield decides (assessment, completion rule, monitor, enabled, actuation delay it "
        "accounts for, own lane, sensing; safelane.shield.ShieldConfig).",
    )

    horizon_s: float = Field(10.0, gt=0.0, description="Simulated time [s] (our assumption; the paper's is unstated).")
    brake_start_s: float = Field(0.0, ge=0.0, description="When L(N+1) starts its sudden braking [s] (paper: t = 0).")
    sensor_noise_std: float = Field(0.0, ge=0.0, description="Std of the ego's measurements of F's speed [m/s].")
    follower_open_decel: float = Field(0.5, ge=0.0, description="Collaborative F's gap-opening deceleration [m/s²].")
    follower_open_gap_m: float = Field(3.0, ge=0.0, description="How much a collaborative F opens the gap [m].")
    l1_plan_steps: int = Field(10, ge=1, description="Periods of L1's planned acceleration shared over V2X.")
    v2x_loss: float = Field(
        0.0, ge=0.0, lt=1.0, description="Probability that a V2X message is lost (per sender and period)."
    )
    v2x_latency_periods: int = Field(0, ge=0, le=50, description="V2X messages arrive this many periods late.")
    v2x_max_age_s: float = Field(
        0.3, ge=0.0, description="Older messages are stale: their sender counts as non-connected (safelane.v2x)."
    )
    leader_rule: Literal["worst_case", "reactive"] = Field(
        "worst_case",
        description="How connected leaders brake: 'worst_case' keeps a safe distance against the vehicle ahead's "
        "worst case with their own chain bound (the guarantee's assumption); 'reactive' reacts to the vehicle "
        "ahead's current braking (the paper-faithful preset; outside the guarantee, see docs/simulator.md).",
    )
    follower_ignores_ego: bool = Field(
        False,
        description="Outside the assumptions: F never yields to the ego (it follows L1 only, even after the lane "
        "change completes). For studies of what the guarantee does not cover.",
    )
    # --- Beyond the paper's world (docs/real_roads.md): all off by default (the paper's world) ---
    own_lane: bool = Field(False, description="Put a leader L0 ahead of the ego in its own lane (non-connected).")
    l0_gap_min_m: float = Field(15.0, gt=0.0, description="L0's initial gap to the ego: smallest [m].")
    l0_gap_max_m: float = Field(60.0, gt=0.0, description="L0's initial gap to the ego: largest [m].")
    l0_speed_spread_mps: float = Field(3.0, ge=0.0, description="L0's initial speed: the ego's + up to this [m/s].")
    l0_decel_mps2: float | None = Field(None, gt=0.0, description="L0's sudden braking [m/s²] (default a_x_d).")
    l0_brake_window_s: float = Field(4.0, ge=0.0, description="L0 starts braking at a uniform instant in [0, this].")
    own_lane_connected: int = Field(0, ge=0, le=8, description="How many vehicles from L0 on are connected (V2X: "
                                    "state and a promised maximum deceleration); the vehicle ahead of them, not "
                                    "connected, brakes as L0 does with 0 (docs/real_roads.md, 'A connected own "
                                    "lane'). Each is placed l0_gap_* ahead of the one behind it, not slower "
                                    "than it by more than 0, faster by up to l0_speed_spread_mps.")  # fmt: skip
    own_promise_decel: float = Field(0.5, ge=0.0, description="The connected own-lane vehicles' promised maximum "
                                     "deceleration [m/s²] (the paper's a_m_d); each brakes at it from an instant "
                                     "uniform in [0, l0_brake_window_s].")  # fmt: skip
    sensing_error: bool = Field(False, description="The ego measures the others with errors inside SensingBounds.")
    sense_connected_pos_m: float = Field(0.5, ge=0.0, description="Position error bound, connected vehicles [m].")
    sense_connected_speed_mps: float = Field(0.2, ge=0.0, description="Speed error bound, connected [m/s].")
    sense_sensed_pos_m: float = Field(1.0, ge=0.0, description="Position error bound, non-connected vehicles [m].")
    sense_sensed_speed_mps: float = Field(0.5, ge=0.0, description="Speed error bound, non-connected [m/s].")
    sensing_edge_share: float = Field(0.0, ge=0.0, le=1.0, description="Share of measurement errors drawn at the "
                                      "ends of their bounds (the falsifier's corners; 0: uniform inside).")  # fmt: skip
    actuation_delay_s: float = Field(0.0, ge=0.0, le=1.0, description="Actuation delay [s], whole control periods.")
    # --- Beyond the paper's two lanes (docs/simulator.md, "Neighbours"): off by default ---
    neighbours: bool = Field(False, description="Traffic in the lane beyond the target lane and on the ego's "
                             "other side (non-connected platoons keeping their lanes; safelane.sim.neighbours): the "
                             "shield's world model counts them, so the run measures what the multi-lane world "
                             "costs.")  # fmt: skip
    neighbour_headway_min_s: float = Field(1.0, gt=0.0, description="Neighbours' time headway: shortest [s].")
    neighbour_headway_max_s: float = Field(3.0, gt=0.0, description="Neighbours' time headway: longest [s].")
    neighbour_speed_spread_mps: float = Field(3.0, ge=0.0, description="A neighbour lane's speed: the ego's initial "
                                              "speed + uniform in [-this, this] [m/s].")  # fmt: skip

    @model_validator(mode="before")
    @classmethod
    def _shield_keys(cls, data):
        """The flat keys of :data:`SHIELD_KEYS` and ``shield_delay`` into ``shield`` (see the module docstring)."""
        if not isinstance(data, dict):
            return data
        data = dict(data)
        shield = data.get("shield", {})
        shield = dict(shield.model_dump() if isinstance(shield, ShieldConfig) else shield)
        for old, new in SHIELD_KEYS.items():
            if old in data:
                if new in shield and "shield" in data:
                    raise ValueError(f"{old} and shield.{new} both given: give one (shield.{new})")
                shield[new] = data.pop(old)
        accounts = data.pop("shield_delay", None)
        if accounts is not None and "actuation_delay_s" in shield and "shield" in data:
            raise ValueError("shield_delay and shield.actuation_delay_s both given: give one of them")
        if "actuation_delay_s" not in shield or accounts is not None:
            world = data.get("actuation_delay_s", cls.model_fields["actuation_delay_s"].default)
            shield["actuation_delay_s"] = world if accounts is None or bool(accounts) else 0.0
        data["shield"] = shield
        return data

    def model_copy(self, *, update=None, deep: bool = False) -> SimConfig:
        """A copy with ``update`` applied and validated (pydantic's own skips validation): flat shield keys and
        ``shield_delay`` read as in the constructor; the shield's delay follows a change of the world's where it
        was equal to it (the shield accounted for it)."""
        if not update:
            return super().model_copy(deep=deep)
        update = dict(update)
        data = self.model_dump()
        shield = update.pop("shield", {})
        shield = dict(shield.model_dump() if isinstance(shield, ShieldConfig) else shield)
        for old, new in SHIELD_KEYS.items():
            if old in update:
                shield[new] = update.pop(old)
        follows = self.shield.actuation_delay_s == self.actuation_delay_s
        accounts = update.pop("shield_delay", None)
        if accounts is not None:  # the shield accounts for the world's delay (as it is after this update), or not
            if "actuation_delay_s" in shield:
                raise ValueError("shield_delay and shield.actuation_delay_s both given: give one of them")
            shield["actuation_delay_s"] = update.get("actuation_delay_s", self.actuation_delay_s) if accounts else 0.0
        elif "actuation_delay_s" in update and "actuation_delay_s" not in shield:
            shield["actuation_delay_s"] = update["actuation_delay_s"] if follows else self.shield.actuation_delay_s
        data.update(update)
        data["shield"] = {**data["shield"], **shield}
        return type(self).model_validate(data)

    @model_validator(mode="after")
    def _check_l0(self) -> SimConfig:
        if self.l0_gap_max_m < self.l0_gap_min_m:
            raise ValueError(f"l0_gap_max_m={self.l0_gap_max_m} must be >= l0_gap_min_m={self.l0_gap_min_m}")
        if self.neighbour_headway_max_s < self.neighbour_headway_min_s:
            raise ValueError(f"neighbour_headway_max_s={self.neighbour_headway_max_s} must be >= "
                             f"neighbour_headway_min_s={self.neighbour_headway_min_s}")  # fmt: skip
        return self

    def sensing_bounds(self):
        from ..shield.situation import SensingBounds

        return SensingBounds(self.sense_connected_pos_m, self.sense_connected_speed_mps, self.sense_sensed_pos_m,
                             self.sense_sensed_speed_mps)  # fmt: skip

