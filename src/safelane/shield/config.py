"""How the shield decides (:class:`ShieldConfig`): its one configuration surface; the simulator's
:class:`~safelane.sim.config.SimConfig` carries one."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, field_validator

from .policies import ASSESSMENTS, COMPLETION_RULES, check_policy


class ShieldConfig(BaseModel):
    """How the shield decides (not what it knows: that is the :class:`Situation`)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    assessment: str = Field("observed", description="Registered assessment model ('observed', 'truth').")
    assess_window: int = Field(5, ge=2, description="Observations in the assessment's slope window.")
    assess_threshold: float = Field(0.2, gt=0.0, description="Evidence threshold on F's acceleration [m/s²].")
    monitor: bool = Field(True, description="After a breach of the assumptions, assume the worst (L1 at a_x_d, F "
                          "aggressive); False only records breaches.")  # fmt: skip
    completion: str = Field("commit_guard", description="Registered completion rule.")
    assess_delay_s: float = Field(1.5, ge=0.0, description="'slow' assessment: mean extra delay of a verdict [s].")
    assess_miss: float = Field(0.0, ge=0.0, le=1.0, description="'slow' assessment: P(a collaborative F is missed).")
    enabled: bool = Field(True, description="False passes the (clipped, checked) proposal through unfiltered.")
    actuation_delay_s: float = Field(0.0, ge=0.0, le=1.0, description="Actuation delay δ [s]: a command acts δ after "
                                     "it is issued, the ones issued before keep acting meanwhile; a whole number of "
                                     "control periods (0 = the paper).")  # fmt: skip
    own_lane: bool = Field(True, description="Keep p_m to the own-lane leaders (L0) the situation carries; False "
                           "ignores them (the paper's shield, which assumes an empty original lane).")  # fmt: skip
    sensing: bool = Field(True, description="Take the worst case over the situation's sensing-error bounds; False "
                          "takes the measurements as exact (the paper's shield).")  # fmt: skip

    @field_validator("assessment")
    @classmethod
    def _assessment(cls, value: str) -> str:
        return check_policy("assessment", value, ASSESSMENTS)

    @field_validator("completion")
    @classmethod
    def _completion(cls, value: str) -> str:
        return check_policy("completion rule", value, COMPLETION_RULES)
