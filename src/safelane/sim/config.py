"""Settings of a simulation run (not of the scenario distribution)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class SimConfig(BaseModel):
    """Settings of a simulation run (not of the scenario distribution)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    horizon_s: float = Field(10.0, gt=0.0, description="Simulated time [s] (our assumption; the paper's is unstated).")
    brake_start_s: float = Field(0.0, ge=0.0, description="When L(N+1) starts its sudden braking [s] (paper: t = 0).")
    assessment: Literal["observed", "truth", "slow"] = Field(
        "observed",
        description="'truth' replaces the aggressiveness assessment by F's true type; 'slow' delays the observed "
        "one's 'collaborative' verdicts and misses some (safelane.shield.policies).",
    )
    assess_delay_s: float = Field(1.5, ge=0.0, description="'slow' assessment: mean extra delay of a verdict [s].")
    assess_miss: float = Field(0.0, ge=0.0, le=1.0, description="'slow' assessment: P(a collaborative F is missed).")
    completion: Literal["commit_guard", "paper_evasion", "paper_body_across"] = Field(
        "commit_guard",
        description="Completion rule of the step that crosses the lane boundary: 'commit_guard' (safe mode; the "
        "guarantee's), 'paper_evasion' (the paper's Eq. 9 evasion check only) or 'paper_body_across' (the same, "
        "completing only once the whole car is across; before that the ego may still turn back).",
    )
    sensor_noise_std: float = Field(0.0, ge=0.0, description="Std of the ego's measurements of F's speed [m/s].")
    assess_window: int = Field(5, ge=2, description="Observations in the assessment's slope window.")
    assess_threshold: float = Field(0.2, gt=0.0, description="Evidence threshold on F's acceleration [m/s²].")
    follower_open_decel: float = Field(0.5, ge=0.0, description="Collaborative F's gap-opening deceleration [m/s²].")
    follower_open_gap_m: float = Field(3.0, ge=0.0, description="How much a collaborative F opens the gap [m].")
    l1_plan_steps: int = Field(10, ge=1, description="Periods of L1's planned acceleration shared over V2X.")
    supervised: bool = Field(True, description="False runs the nominal planner without the safety supervisor.")
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
    monitor: bool = Field(
        True,
        description="After a breach of the assumptions (safelane.shield.monitor) use the most conservative ones "
        "(L1 at a_x_d, F aggressive). False only records breaches.",
    )
    # --- Beyond the paper's world (docs/real_roads.md): all off by default (the paper's world) ---
    own_lane: bool = Field(False, description="Put a leader L0 ahead of the ego in its own lane (non-connected).")
    l0_gap_min_m: float = Field(15.0, gt=0.0, description="L0's initial gap to the ego: smallest [m].")
    l0_gap_max_m: float = Field(60.0, gt=0.0, description="L0's initial gap to the ego: largest [m].")
    l0_speed_spread_mps: float = Field(3.0, ge=0.0, description="L0's initial speed: the ego's + up to this [m/s].")
    l0_decel_mps2: float | None = Field(None, gt=0.0, description="L0's sudden braking [m/s²] (default a_x_d).")
    l0_brake_window_s: float = Field(4.0, ge=0.0, description="L0 starts braking at a uniform instant in [0, this].")
    sensing_error: bool = Field(False, description="The ego measures the others with errors inside SensingBounds.")
    sense_connected_pos_m: float = Field(0.5, ge=0.0, description="Position error bound, connected vehicles [m].")
    sense_connected_speed_mps: float = Field(0.2, ge=0.0, description="Speed error bound, connected [m/s].")
    sense_sensed_pos_m: float = Field(1.0, ge=0.0, description="Position error bound, non-connected vehicles [m].")
    sense_sensed_speed_mps: float = Field(0.5, ge=0.0, description="Speed error bound, non-connected [m/s].")
    sensing_edge_share: float = Field(0.0, ge=0.0, le=1.0, description="Share of measurement errors drawn at the "
                                      "ends of their bounds (the falsifier's corners; 0: uniform inside).")  # fmt: skip
    actuation_delay_s: float = Field(0.0, ge=0.0, le=1.0, description="Actuation delay [s], whole control periods.")
    shield_own_lane: bool = Field(True, description="The shield keeps p_m to L0 (False: the paper's shield).")
    shield_sensing: bool = Field(True, description="The shield takes the worst case over the error bounds (False: "
                                 "it trusts measurements, as the paper's).")  # fmt: skip
    shield_delay: bool = Field(True, description="The shield accounts for the actuation delay (False: the paper's).")

    @model_validator(mode="after")
    def _check_l0(self) -> SimConfig:
        if self.l0_gap_max_m < self.l0_gap_min_m:
            raise ValueError(f"l0_gap_max_m={self.l0_gap_max_m} must be >= l0_gap_min_m={self.l0_gap_min_m}")
        return self

    def sensing_bounds(self):
        from ..shield.situation import SensingBounds

        return SensingBounds(self.sense_connected_pos_m, self.sense_connected_speed_mps, self.sense_sensed_pos_m,
                             self.sense_sensed_speed_mps)  # fmt: skip

