"""Physical and geometric parameters of the lane-change problem.

``Params`` is frozen and validated: every field is finite, has a physical range, and carries the source of
its default. Invalid values raise :class:`ValueError` (pydantic's ``ValidationError`` is a subclass) naming
the field and the offending value.

Symbols (paper → field): ``a_{x,a}`` → ``a_x_a``, ``a_{x,d}`` → ``a_x_d``, ``a_{y,m}`` → ``a_y_m``,
``w_l`` → ``lane_width``, ``w_v`` → ``vehicle_width``, ``p_m`` → ``p_m``.

**Braking limits** (RSS's split, Shalev-Shwartz et al. 2017 §3; ad-rss's ``RssDynamics``): ``a_x_d`` is the braking
the ego *commits to* — the deceleration of its evasion (Eqs. 6–8), the strongest braking the shield ever commands, and
its assumption about a collaborative ``F`` (Eq. 9) — RSS's ``brakeMin`` for the ego's proper response. ``a_o_d`` is
the strongest braking any *other* vehicle may use (RSS's ``brakeMax``): ``L(N+1)``, a non-connected ``L1``/``L0``, and
the physical cap of a connected leader beyond its promise. ad-rss's defaults are ``brakeMin`` 4, ``brakeMax`` 8 m/s²;
measured emergency braking of modern passenger cars on dry asphalt is about 9–10 m/s² (Greibe 2007, *Braking
distance, friction and behaviour*, Trafitec; Kudarauskas 2007, *Analysis of emergency braking of a vehicle*,
Transport 22(3)). The ego's own physical maximum is
not a parameter: nothing the shield does brakes harder than ``a_x_d``, so the guarantee needs only ``a_x_d`` to be
within it (``docs/safety.md``, "What each vehicle may do").
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

_Positive = Annotated[float, Field(gt=0.0)]


class Params(BaseModel):
    """Mechanical limits, geometry and safety distances shared by every vehicle.

    Sign convention: accelerations and decelerations are magnitudes (positive numbers); the
    longitudinal axis points in the direction of travel and the lateral axis from the original lane
    (centre ``y = 0``) to the target lane (centre ``y = lane_width``).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    a_x_a: _Positive = Field(
        2.5, description="Max longitudinal acceleration [m/s²]. Our assumption — calibrated in a later issue."
    )
    a_x_d: _Positive = Field(
        8.0,
        description="Max longitudinal deceleration, positive [m/s²]. Our assumption (covers the paper's "
        "sudden braking of up to 6 m/s² and the simulator tests' 8 m/s²) — calibrated in a later issue.",
    )
    a_o_d: float | None = Field(
        None,
        ge=0.0,
        description="Others' maximum braking, positive [m/s²] (RSS's brakeMax): L(N+1), a non-connected L1 or L0, and "
        "the physical cap of every connected leader. None: a_x_d, the paper's world (every vehicle brakes no harder "
        "than the ego). Real cars: 9–10 m/s² (Greibe 2007; Kudarauskas 2007); ad-rss's default brakeMax is 8.",
    )
    a_y_m: _Positive = Field(
        1.5, description="Max lateral acceleration magnitude [m/s²]. Our assumption — calibrated in a later issue."
    )
    lane_width: _Positive = Field(3.5, description="Lane width w_l [m]. Our assumption (typical highway lane).")
    vehicle_width: _Positive = Field(1.8, description="Vehicle width w_v [m]. Our assumption (passenger car).")
    vehicle_length: _Positive = Field(4.8, description="Vehicle length [m]. Our assumption (passenger car).")
    p_m: _Positive = Field(
        7.0,
        description="Minimum safe longitudinal distance between reference points (centres) [m]. "
        "Our assumption — calibrated in a later issue.",
    )
    p_m_human: _Positive = Field(
        10.0,
        description="Larger minimum distance kept by/for connected human-driven vehicles [m] (paper footnote 1). "
        "Our assumption.",
    )
    dt: _Positive = Field(0.1, description="Control period [s]. ASP-DAC'23 / paper.")

    @model_validator(mode="after")
    def _check_consistency(self) -> Params:
        if self.vehicle_width >= self.lane_width:
            raise ValueError(f"vehicle_width={self.vehicle_width} must be smaller than lane_width={self.lane_width}")
        if self.p_m < self.vehicle_length:
            raise ValueError(
                f"p_m={self.p_m} must be at least vehicle_length={self.vehicle_length}: "
                "a gap of p_m between centres must mean the vehicles do not overlap"
            )
        if self.p_m_human < self.p_m:
            raise ValueError(f"p_m_human={self.p_m_human} must be at least p_m={self.p_m}")
        return self

    @property
    def others_decel(self) -> float:
        """The others' maximum braking ``a_o_d`` as a number: ``a_x_d`` where it is not set (the paper's world)."""
        return self.a_x_d if self.a_o_d is None else self.a_o_d

    @property
    def y_safe(self) -> float:
        """Lateral centre position at which the ego lies wholly in its original lane: ``(w_l − w_v)/2``."""
        return 0.5 * (self.lane_width - self.vehicle_width)

    @property
    def y_boundary(self) -> float:
        """Lateral position of the lane boundary; the lane change completes when the centre crosses it."""
        return 0.5 * self.lane_width
