"""Responsibility-Sensitive Safety (Shalev-Shwartz et al. 2017) as ad-rss 5.0 implements it, vectorized in NumPy.

Symbols (ad-rss's names, ``ad::rss::world::RssDynamics``): response time ρ (``response_time``, the ego's and the
other vehicles' apart), ``accel_max`` (α_accel,max), ``brake_min`` (α_brake,min), ``brake_max`` (α_brake,max),
``brake_min_correct`` (α_brake,min,correct), the lateral ``accel_max``/``brake_min`` (α^lat), the lateral
fluctuation margin μ, ``max_speed_on_acceleration`` and ``min_longitudinal_safety_distance``.

Sign convention: ad-rss stores braking as negative accelerations (``brake_max = -8``); here, as everywhere in
safelane, every acceleration and deceleration is a positive magnitude (``brake_max = 8``).
:mod:`.rss_adrss` converts.

The closed forms (``ad_rss/src/structured/RssFormulas.cpp`` and ``core/Physics.cpp`` of ad-rss 5.0), as functions
of arrays of any (broadcastable) shape:

* :func:`longitudinal_safe_distance` — same direction (``calculateSafeLongitudinalDistanceSameDirection``): the rear
  vehicle accelerates at ``accel_max`` for its response time (up to ``max_speed_on_acceleration``), then brakes at
  ``brake_min`` to a stop; the front one brakes at ``brake_max`` from its lowest speed. ``d_min = max(rear's
  distance − front's stopping distance, 0) + min_longitudinal_safety_distance`` (bumper to bumper).
* :func:`lateral_safe_distance` — ``calculateSafeLateralDistance``: each vehicle accelerates towards the other at
  the lateral ``accel_max`` for its response time, then brakes laterally at ``brake_min`` to zero lateral speed;
  ``d_min = max(the two offsets + μ, 0)`` (edge to edge).
* :func:`is_safe` — ad-rss's verdict ``distance > d_min``, with ad-rss's comparison: ``ad::physics`` values compare
  equal within their precision (distances and speeds 1e-3, accelerations 1e-4), so "greater" means greater by at
  least 1 mm. The clamps (``max(·, 0)``, the speed limits) use the same comparison; the NumPy version does too, so the
  verdicts are identical, not just close.

Lateral axis: ad-rss's points from the left vehicle to the right one; safelane's ``y`` points from the original lane
to the target lane, taken as the left one, so an ad-rss lateral speed is ``−vy``.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ..params import Params
from ..safety._backend import ARRAY, INF, jitable

#: ``ad::physics`` precisions: two values closer than this compare equal.
DISTANCE_PRECISION_M = 1e-3
SPEED_PRECISION_MPS = 1e-3

_Pos = Field(gt=0.0)


class RssParams(BaseModel):
    """RSS's parameters in ad-rss's vocabulary (magnitudes, positive). Defaults: ad-rss's documented starting values
    (ad-rss-lib, *Appendix: Parameter Discussion*, "As a starting point the values are set to": ρ_ego 1 s, ρ_other
    2 s, α_accel,max 3.5, α_brake,min 4, α_brake,max 8, α_brake,min,correct 3, α^lat_brake,min 0.8,
    α^lat_accel,max 0.2 m/s², μ 0.1 m); ``max_speed_on_acceleration`` and ``min_longitudinal_safety_distance`` are
    ``RssDynamics``'s own defaults (100 m/s, 0 m)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    response_time_ego: float = Field(1.0, gt=0.0, le=10.0, description="ρ of the ego [s] (ad-rss: 1 s).")
    response_time_other: float = Field(2.0, gt=0.0, le=10.0, description="ρ of every other vehicle [s] (2 s).")
    accel_max: float = Field(3.5, gt=0.0, description="α_accel,max: longitudinal acceleration during ρ [m/s²].")
    brake_min: float = Field(4.0, gt=0.0, description="α_brake,min: the least braking of a responsible rear "
                             "vehicle [m/s²].")  # fmt: skip
    brake_max: float = Field(8.0, gt=0.0, description="α_brake,max: the hardest braking of a front vehicle [m/s²].")
    brake_min_correct: float = Field(3.0, gt=0.0, description="α_brake,min,correct: opposite-direction braking of "
                                     "the vehicle in its correct lane [m/s²] (unused on one-way lanes).")  # fmt: skip
    lat_accel_max: float = Field(0.2, gt=0.0, description="α^lat_accel,max: lateral acceleration during ρ [m/s²].")
    lat_brake_min: float = Field(0.8, gt=0.0, description="α^lat_brake,min: the least lateral braking [m/s²].")
    lateral_fluctuation_margin: float = Field(0.1, ge=0.0, description="μ: lateral fluctuation margin [m].")
    max_speed_on_acceleration: float = Field(100.0, gt=0.0, description="Speed the acceleration during ρ stops "
                                             "at [m/s] (RssDynamics default).")  # fmt: skip
    min_longitudinal_safety_distance: float = Field(0.0, ge=0.0, description="Added to every longitudinal safe "
                                                    "distance [m] (RssDynamics default 0).")  # fmt: skip

    @model_validator(mode="after")
    def _ordered(self) -> RssParams:
        if self.brake_min > self.brake_max:
            raise ValueError(f"brake_min={self.brake_min} must not exceed brake_max={self.brake_max}")
        if self.brake_min_correct > self.brake_min:
            raise ValueError(f"brake_min_correct={self.brake_min_correct} must not exceed brake_min={self.brake_min}")
        return self

    @classmethod
    def matched(cls, params: Params) -> RssParams:
        """RSS with this world's limits: ρ one control period for everyone (the shield re-decides every period), the
        simulator's accelerations (``a_x_a``; braking ``a_x_d`` for ``brake_min`` and ``brake_max`` alike, so a
        responsible rear vehicle brakes as hard as anyone can: RSS at its least conservative), the lateral limit
        ``a_y_m``; ad-rss's μ."""
        return cls(
            response_time_ego=params.dt, response_time_other=params.dt, accel_max=params.a_x_a,
            brake_min=params.a_x_d, brake_max=params.a_x_d, brake_min_correct=params.a_x_d,
            lat_accel_max=params.a_y_m, lat_brake_min=params.a_y_m,
        )  # fmt: skip


#: Named RSS parameter sets: name -> ``(Params) -> RssParams``.
RSS_PARAMETER_SETS = {"ad_rss": lambda params: RssParams(), "matched": RssParams.matched}


@lru_cache(maxsize=64)
def rss_params_for(name: str, params: Params) -> RssParams:
    """The registered parameter set ``name`` for the world ``params``."""
    try:
        return RSS_PARAMETER_SETS[name](params)
    except KeyError:
        raise ValueError(f"unknown RSS parameter set {name!r}; choose one of {', '.join(RSS_PARAMETER_SETS)}") from None


class RssRecord(NamedTuple):
    """The parameters the closed forms read, as a record numba can take (the compiled kernels build one per row from
    a float vector, :data:`RSS_FIELDS`); uncompiled code passes :class:`RssParams` itself (the same attribute names)."""

    response_time_ego: float
    response_time_other: float
    accel_max: float
    brake_min: float
    brake_max: float
    lat_accel_max: float
    lat_brake_min: float
    lateral_fluctuation_margin: float
    max_speed_on_acceleration: float
    min_longitudinal_safety_distance: float


#: The :class:`RssParams` fields a compiled rule reads, in :class:`RssRecord`'s order.
RSS_FIELDS = RssRecord._fields


def rss_vector(rss: RssParams) -> np.ndarray:
    """``rss``'s :data:`RSS_FIELDS` as floats (what a compiled kernel turns back into an :class:`RssRecord`)."""
    return np.array([getattr(rss, name) for name in RSS_FIELDS], float)


# The closed forms, written once against the backend ``xp`` (``safety/_backend.py``): NumPy arrays through the public
# functions below, floats compiled into the shield's period (``shield/_fast_period.py``). Negations are comparisons
# written the other way round (``abs(a - b) >= p`` for ad-rss's ``not equal``), which give the same verdicts: where
# either side is NaN, the other conjunct is false already.


def greater_core(xp, a, b, precision):
    """``ad::physics``'s ``a > b``: greater, and not equal within ``precision``."""
    return (a > b) & (abs(a - b) >= precision)


def clamp0_core(xp, x, precision):
    """``std::max(x, 0)`` with ``ad::physics``'s ``<`` (a value within ``precision`` below 0 stays as it is)."""
    return xp.where((x < 0.0) & (abs(x) >= precision), 0.0, x)


def stated_longitudinal_core(xp, v, response_time, accel_max, brake_min, max_speed):
    """Backend-generic :func:`stated_braking_longitudinal`."""
    v_r = v + accel_max * response_time
    v_r = xp.where(greater_core(xp, v_r, 0.0, SPEED_PRECISION_MPS), v_r, 0.0)
    limit = xp.where(greater_core(xp, v, max_speed, SPEED_PRECISION_MPS), v, max_speed)
    v_r = xp.where((v_r < limit) | (abs(v_r - limit) < SPEED_PRECISION_MPS), v_r, limit)
    t_acc = (v_r - v) / accel_max
    offset = v * response_time + 0.5 * accel_max * t_acc * t_acc + (v_r - v) * (response_time - t_acc)
    return offset + v_r * v_r / (2.0 * brake_min)


def longitudinal_core(xp, v_front, v_rear, response_time_rear, accel_max_rear, brake_min_rear, brake_max_front,
                      max_speed_rear, min_distance_rear):  # fmt: skip
    """Backend-generic :func:`longitudinal_safe_distance`."""
    rear = stated_longitudinal_core(xp, v_rear, response_time_rear, accel_max_rear, brake_min_rear, max_speed_rear)
    front = v_front * v_front / (2.0 * brake_max_front)
    return clamp0_core(xp, rear - front, DISTANCE_PRECISION_M) + min_distance_rear


def longitudinal_exact_core(xp, v_front, v_rear, response_time_rear, accel_max_rear, brake_min_rear, brake_max_front,
                            max_speed_rear, min_distance_rear):  # fmt: skip
    """Backend-generic :func:`longitudinal_safe_distance_exact` (where the rear vehicle does not brake harder, the
    interior candidate is ``-inf`` and the closed form stands)."""
    closed = longitudinal_core(xp, v_front, v_rear, response_time_rear, accel_max_rear, brake_min_rear,
                               brake_max_front, max_speed_rear, min_distance_rear)  # fmt: skip
    harder = brake_min_rear > brake_max_front
    rho = response_time_rear
    v_rho = xp.minimum(v_rear + accel_max_rear * rho, xp.maximum(max_speed_rear, v_rear))
    t_acc = (v_rho - v_rear) / accel_max_rear
    d_rho = v_rear * rho + 0.5 * accel_max_rear * t_acc * t_acc + (v_rho - v_rear) * (rho - t_acc)
    t_star = xp.div(v_rho + brake_min_rear * rho - v_front, brake_min_rear - brake_max_front, 0.0)
    t_stop = xp.minimum(v_front / brake_max_front, rho + v_rho / brake_min_rear)
    inside = harder & (t_star >= rho) & (t_star <= t_stop)
    tr = t_star - rho
    closing = d_rho + v_rho * tr - 0.5 * brake_min_rear * tr * tr - (v_front * t_star - 0.5 * brake_max_front
                                                                      * t_star * t_star)  # fmt: skip
    interior = xp.where(inside, xp.maximum(closing, 0.0) + min_distance_rear, -INF)
    return xp.maximum(closed, interior)


def stated_lateral_core(xp, v_towards, response_time, lat_accel_max, lat_brake_min):
    """Backend-generic :func:`stated_braking_lateral` (a lateral speed of ``-0.0`` after the response time adds
    ``+0.0``, as ad-rss's sign test does)."""
    v_r = v_towards + lat_accel_max * response_time
    offset = lat_accel_max * 0.5 * response_time * response_time + v_towards * response_time
    return offset + xp.where(v_r < 0.0, 0.0, v_r * v_r / (2.0 * lat_brake_min))


def lateral_core(xp, v_left, response_time_left, v_right, response_time_right, lat_accel_max, lat_brake_min,
                 margin_left, margin_right, lat_accel_max_right, lat_brake_min_right):  # fmt: skip
    """Backend-generic :func:`lateral_safe_distance` (every argument given)."""
    left = stated_lateral_core(xp, v_left, response_time_left, lat_accel_max, lat_brake_min)
    # The right vehicle moves towards the left one in ad-rss's negative direction: its offset is -(distance covered).
    right = -stated_lateral_core(xp, -v_right, response_time_right, lat_accel_max_right, lat_brake_min_right)
    return clamp0_core(xp, left - right + 0.5 * (margin_left + margin_right), DISTANCE_PRECISION_M)


def pair_core(xp, ego_x, ego_y, ego_vx, ego_vy, x, y, vx, vy, rss, length, width, brake_other):
    """Backend-generic :func:`pair_check` (``rss``: :class:`RssParams` or :class:`RssRecord`; ``length``, ``width``:
    the vehicles'): ``(safe, lon_safe, lat_safe, lon_distance, lon_safe_distance, lat_distance,
    lat_safe_distance)``."""
    ego_vx, vx = xp.maximum(ego_vx, 0.0), xp.maximum(vx, 0.0)  # ad-rss takes speeds >= 0 (vehicles stop)
    ahead = x > ego_x
    lon_distance = xp.maximum(abs(x - ego_x) - length, 0.0)
    # One evaluation for both orders: the rear vehicle is the ego where the other is ahead.
    lon_safe_distance = longitudinal_exact_core(
        xp, xp.where(ahead, vx, ego_vx), xp.where(ahead, ego_vx, vx),
        xp.where(ahead, rss.response_time_ego, rss.response_time_other), rss.accel_max, rss.brake_min,
        xp.where(ahead, brake_other, rss.brake_max), rss.max_speed_on_acceleration,
        rss.min_longitudinal_safety_distance,
    )  # fmt: skip
    left = y > ego_y  # the other vehicle is on the left (towards the target lane)
    lat_distance = xp.maximum(abs(y - ego_y) - width, 0.0)
    rho_l = xp.where(left, rss.response_time_other, rss.response_time_ego)
    rho_r = xp.where(left, rss.response_time_ego, rss.response_time_other)
    v_l = xp.where(left, -vy, -ego_vy)  # ad-rss's lateral axis points right: speed = -vy
    v_r = xp.where(left, -ego_vy, -vy)
    mu = rss.lateral_fluctuation_margin
    lat_safe_distance = lateral_core(xp, v_l, rho_l, v_r, rho_r, rss.lat_accel_max, rss.lat_brake_min, mu, mu,
                                     rss.lat_accel_max, rss.lat_brake_min)  # fmt: skip
    lon_safe = greater_core(xp, lon_distance, lon_safe_distance, DISTANCE_PRECISION_M)
    lat_safe = greater_core(xp, lat_distance, lat_safe_distance, DISTANCE_PRECISION_M)
    return lon_safe | lat_safe, lon_safe, lat_safe, lon_distance, lon_safe_distance, lat_distance, lat_safe_distance


def is_safe(distance_m, safe_distance_m):
    """ad-rss's verdict ``distance > safe distance`` (greater by at least the 1 mm precision)."""
    return greater_core(ARRAY, np.asarray(distance_m, float), safe_distance_m, DISTANCE_PRECISION_M)


def stated_braking_longitudinal(v, response_time, accel_max, brake_min, max_speed=100.0):
    """Distance a vehicle at speed ``v >= 0`` covers under RSS's stated braking pattern: ``accel_max`` for the
    response time (speed limited to ``max(max_speed, v)``, never below 0), then ``brake_min`` to a stop
    (``calculateLongitudinalDistanceOffsetAfterStatedBrakingPattern``)."""
    return stated_longitudinal_core(ARRAY, np.asarray(v, float), response_time, accel_max, brake_min, max_speed)


def longitudinal_safe_distance(
    v_front, v_rear, response_time_rear, accel_max_rear, brake_min_rear, brake_max_front, max_speed_rear=100.0,
    min_distance_rear=0.0,
):  # fmt: skip
    """RSS's safe longitudinal distance (bumper to bumper), same direction [m]; arrays broadcast.

    ``v_front``: the front vehicle's (lowest) speed; ``v_rear``: the rear vehicle's (highest) speed, both ``>= 0``;
    the rear vehicle's response time, ``accel_max``, ``brake_min``, ``max_speed_on_acceleration`` and
    ``min_longitudinal_safety_distance``; the front vehicle's ``brake_max``.
    """
    return longitudinal_core(ARRAY, np.asarray(v_front, float), np.asarray(v_rear, float), response_time_rear,
                             accel_max_rear, brake_min_rear, brake_max_front, max_speed_rear,
                             min_distance_rear)  # fmt: skip


def longitudinal_safe_distance_exact(
    v_front, v_rear, response_time_rear, accel_max_rear, brake_min_rear, brake_max_front, max_speed_rear=100.0,
    min_distance_rear=0.0,
):  # fmt: skip
    """:func:`longitudinal_safe_distance` where it is a certificate, and the exact worst-case closing otherwise.

    RSS's closed form compares where the two vehicles stop; that bounds the closing at every instant only when the
    front vehicle brakes at least as hard as the rear one (``brake_max_front >= brake_min_rear``, which ad-rss's
    parameter checks ensure for one shared parameter set). With V2X a connected front vehicle's ``brake_max`` is its
    promised bound and may be lower: a faster rear vehicle braking harder stops shorter yet can hit it before
    (measured here: 57 % collisions for ``RSS_V2X_matched`` with the closed form alone). There the largest closing
    is reached when the speeds become equal after the response time, ``t* = (v_ρ + brake_min·ρ − v_f)/(brake_min −
    brake_max_front)``; the safe distance is the larger of the two. Identical to ad-rss wherever its lemma holds.
    """
    with np.errstate(invalid="ignore", over="ignore"):  # (the interior candidate where it is not used)
        return longitudinal_exact_core(ARRAY, np.asarray(v_front, float), np.asarray(v_rear, float),
                                       response_time_rear, accel_max_rear, brake_min_rear, brake_max_front,
                                       max_speed_rear, min_distance_rear)  # fmt: skip


def stated_braking_lateral(v_towards, response_time, lat_accel_max, lat_brake_min):
    """Lateral distance a vehicle covers towards the other under RSS's stated braking pattern, from its lateral
    speed towards the other ``v_towards`` (negative: moving away): ``lat_accel_max`` towards the other for the
    response time, then ``lat_brake_min`` to zero lateral speed if still moving towards it
    (``calculateLateralDistanceOffsetAfterStatedBrakingPattern``)."""
    return stated_lateral_core(ARRAY, np.asarray(v_towards, float), response_time, lat_accel_max, lat_brake_min)


def lateral_safe_distance(
    v_left, response_time_left, v_right, response_time_right, lat_accel_max, lat_brake_min, margin_left,
    margin_right=None, lat_accel_max_right=None, lat_brake_min_right=None,
):  # fmt: skip
    """RSS's safe lateral distance (edge to edge) [m]; arrays broadcast.

    ``v_left``, ``v_right``: lateral speeds in ad-rss's axis (positive from the left vehicle towards the right one:
    the left vehicle's highest, the right vehicle's lowest); each vehicle's response time; the lateral
    ``accel_max``/``brake_min`` and μ (the right vehicle's default to the left one's).
    """
    margin_right = margin_left if margin_right is None else margin_right
    a_r = lat_accel_max if lat_accel_max_right is None else lat_accel_max_right
    b_r = lat_brake_min if lat_brake_min_right is None else lat_brake_min_right
    return lateral_core(ARRAY, np.asarray(v_left, float), response_time_left, np.asarray(v_right, float),
                        response_time_right, lat_accel_max, lat_brake_min, margin_left, margin_right, a_r,
                        b_r)  # fmt: skip


def pair_check(ego_x, ego_y, ego_vx, ego_vy, x, y, vx, vy, rss: RssParams, params: Params, brake_max_other=None):
    """RSS between the ego and another vehicle driving the same way, in safelane's frame (centres, ``y`` towards the
    target lane); arrays broadcast. ``brake_max_other``: the other's ``brake_max`` (default ``rss.brake_max``; RSS
    with V2X passes a connected leader's propagated bound).

    Returns ``(safe, lon_safe, lat_safe, lon_distance, lon_safe_distance, lat_distance, lat_safe_distance)``: safe
    is ``lon_safe | lat_safe`` (a situation is dangerous only when both distances are unsafe).
    """
    brake_other = rss.brake_max if brake_max_other is None else brake_max_other
    with np.errstate(invalid="ignore", over="ignore"):
        out = pair_core(ARRAY, ego_x, ego_y, ego_vx, ego_vy, x, y, vx, vy, rss, params.vehicle_length,
                        params.vehicle_width, brake_other)  # fmt: skip
    return tuple(np.broadcast_arrays(*out))


jitable(greater_core, clamp0_core, stated_longitudinal_core, longitudinal_core, longitudinal_exact_core,
        stated_lateral_core, lateral_core, pair_core)
