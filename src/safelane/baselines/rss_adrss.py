"""The reference: RSS's closed forms through ad-rss itself (Intel's ``ad-rss`` 5.0, C++ with Python bindings).

Needs the extra ``rss`` (``pip install 'safelane[rss]'``, i.e. ``ad-rss>=5.0``); imported lazily, so ``import
safelane`` never needs it. One call per pair (ad-rss is scalar): the NumPy version (:mod:`.rss`) is what the shield
runs; this one is what it is tested and timed against.

:func:`pair_check` mirrors :func:`safelane.baselines.rss.pair_check` with ad-rss's
``calculateSafeLongitudinalDistanceSameDirection`` and ``calculateSafeLateralDistance`` and ``ad::physics``'s own
``>`` for the verdict.
"""

from __future__ import annotations

from functools import lru_cache

from ..params import Params
from .rss import RssParams

INSTALL_HINT = "ad-rss is not installed: pip install 'safelane[rss]' (or: pip install 'ad-rss>=5.0')"


def available() -> bool:
    """ad-rss imports."""
    try:
        _modules()
    except ImportError:
        return False
    return True


@lru_cache(maxsize=1)
def _modules():
    import warnings

    try:
        with warnings.catch_warnings():  # its Boost.Python converters warn about each other on import
            warnings.simplefilter("ignore", RuntimeWarning)
            import ad_rss
    except ImportError as exc:
        raise ImportError(INSTALL_HINT) from exc
    return ad_rss, ad_rss.physics, ad_rss.rss.world, ad_rss.rss.core, ad_rss.rss.structured


def dynamics(rss: RssParams, response_time: float, brake_max: float | None = None):
    """An ``ad_rss.rss.world.RssDynamics`` for one vehicle (ad-rss's signs: braking negative)."""
    _, phys, world, _, _ = _modules()
    d = world.RssDynamics()
    lon, lat = d.alpha_lon, d.alpha_lat
    lon.accel_max = phys.Acceleration(rss.accel_max)
    # A front vehicle's own brake_max (RSS with V2X: a connected leader's bound) may lie below brake_min; ad-rss
    # requires brake_max >= brake_min >= brake_min_correct, and a front vehicle's brake_min is never used.
    brake_max = rss.brake_max if brake_max is None else brake_max
    brake_min = min(rss.brake_min, brake_max)
    lon.brake_max = phys.Acceleration(-brake_max)
    lon.brake_min = phys.Acceleration(-brake_min)
    lon.brake_min_correct = phys.Acceleration(-min(rss.brake_min_correct, brake_min))
    lat.accel_max = phys.Acceleration(rss.lat_accel_max)
    lat.brake_min = phys.Acceleration(-rss.lat_brake_min)
    d.lateral_fluctuation_margin = phys.Distance(rss.lateral_fluctuation_margin)
    d.response_time = phys.Duration(response_time)
    d.max_speed_on_acceleration = phys.Speed(rss.max_speed_on_acceleration)
    d.min_longitudinal_safety_distance = phys.Distance(rss.min_longitudinal_safety_distance)
    # Unused by the structured (lane-based) checks, but validated: ad-rss's test-support values.
    u = d.unstructured_settings
    u.pedestrian_turning_radius = phys.Distance(2.0)
    u.drive_away_max_angle = phys.Angle(2.4)
    u.vehicle_yaw_rate_change = phys.AngularAcceleration(0.3)
    u.vehicle_min_radius = phys.Distance(3.5)
    u.vehicle_trajectory_calculation_step = phys.Duration(0.2)
    return d


def object_state(dyn, v_lon: float, v_lat: float, length: float = 4.8, width: float = 1.8):
    """An ``ad_rss.rss.core.RelativeObjectState`` of a vehicle with exact speeds (min = max)."""
    _, phys, world, core, _ = _modules()
    o = core.RelativeObjectState()
    o.object_type = world.ObjectType.OtherVehicle
    o.dynamics = dyn
    vel = o.structured_object_state.velocity
    vel.speed_lon_min = vel.speed_lon_max = phys.Speed(v_lon)
    vel.speed_lat_min = vel.speed_lat_max = phys.Speed(v_lat)
    s = o.structured_object_state
    s.distance_to_enter_intersection = s.distance_to_leave_intersection = phys.Distance(100.0)
    u = o.unstructured_object_state
    u.yaw, u.steering_angle = phys.Angle(0.0), phys.Angle(0.0)
    u.yaw_rate = phys.AngularVelocity(0.0)
    u.dimension.length, u.dimension.width = phys.Distance(length), phys.Distance(width)
    u.center_point.x, u.center_point.y = phys.Distance(0.0), phys.Distance(0.0)
    u.speed_range.minimum = u.speed_range.maximum = phys.Speed(v_lon)
    return o


def safe_longitudinal_distance(front, rear) -> float:
    """ad-rss's ``calculateSafeLongitudinalDistanceSameDirection(front, rear)`` [m]; raises if ad-rss rejects the
    input."""
    _, phys, _, _, structured = _modules()
    out = phys.Distance(0.0)
    if not structured.calculateSafeLongitudinalDistanceSameDirection(front, rear, out):
        raise ValueError("ad-rss rejected the longitudinal input (see its log)")
    return float(out.mDistance)


def safe_lateral_distance(left, right) -> float:
    """ad-rss's ``calculateSafeLateralDistance(left, right)`` [m]."""
    _, phys, _, _, structured = _modules()
    out = phys.Distance(0.0)
    if not structured.calculateSafeLateralDistance(left, right, out):
        raise ValueError("ad-rss rejected the lateral input (see its log)")
    return float(out.mDistance)


def is_safe(distance: float, safe_distance: float) -> bool:
    """``ad::physics::Distance(distance) > Distance(safe_distance)`` — ad-rss's own comparison."""
    _, phys, _, _, _ = _modules()
    return bool(phys.Distance(distance) > phys.Distance(safe_distance))


def pair_check(ego_x, ego_y, ego_vx, ego_vy, x, y, vx, vy, rss: RssParams, params: Params, brake_max_other=None):
    """One pair through ad-rss, with the arguments and results of :func:`safelane.baselines.rss.pair_check`
    (scalars). Where a front vehicle's ``brake_max_other`` lies below ``brake_min`` ad-rss's closed form is no
    certificate and the NumPy version departs from it on purpose (:func:`.rss.longitudinal_safe_distance_exact`)."""
    ego_vx, vx = max(float(ego_vx), 0.0), max(float(vx), 0.0)
    ego_dyn = dynamics(rss, rss.response_time_ego)
    other_dyn = dynamics(rss, rss.response_time_other, brake_max_other if x > ego_x else None)
    # Objects built once per pair (as ad-rss's RssCheck does per object): v_lat in ad-rss's axis is -vy.
    ego = object_state(ego_dyn, ego_vx, -float(ego_vy), params.vehicle_length, params.vehicle_width)
    other = object_state(other_dyn, vx, -float(vy), params.vehicle_length, params.vehicle_width)
    front, rear = (other, ego) if x > ego_x else (ego, other)
    lon_distance = max(abs(x - ego_x) - params.vehicle_length, 0.0)
    lon_safe_distance = safe_longitudinal_distance(front, rear)
    left, right = (other, ego) if y > ego_y else (ego, other)
    lat_distance = max(abs(y - ego_y) - params.vehicle_width, 0.0)
    lat_safe_distance = safe_lateral_distance(left, right)
    lon_safe, lat_safe = is_safe(lon_distance, lon_safe_distance), is_safe(lat_distance, lat_safe_distance)
    return lon_safe or lat_safe, lon_safe, lat_safe, lon_distance, lon_safe_distance, lat_distance, lat_safe_distance


def same_lane_world(ego_v: float, other_v: float, gap_m: float, rss: RssParams, params: Params, *, object_id: int = 1,
                    time_index: int = 1, brake_max_other: float | None = None):  # fmt: skip
    """An ``ad_rss.rss.world.WorldModel`` for ad-rss's full check (``RssCheck.calculateProperResponse``): the ego and
    one other vehicle on one straight lane, the other ``gap_m`` (bumper to bumper) ahead (behind if negative); lateral
    speeds 0. RssCheck keeps a history per object id: give each new situation a new id and a later time index."""
    _, phys, world, _, _ = _modules()
    road_m, lane_w = 10_000.0, params.lane_width

    def vehicle(oid, kind, v, rear_m):
        o = world.Object()
        o.object_id, o.object_type = oid, kind
        o.velocity.speed_lon_min = o.velocity.speed_lon_max = phys.Speed(v)
        o.velocity.speed_lat_min = o.velocity.speed_lat_max = phys.Speed(0.0)
        region = world.OccupiedRegion()
        region.segment_id = 0
        half = 0.5 * params.vehicle_width / lane_w
        region.lat_range.minimum, region.lat_range.maximum = phys.ParametricValue(0.5 - half), phys.ParametricValue(
            0.5 + half)  # fmt: skip
        region.lon_range.minimum = phys.ParametricValue(rear_m / road_m)
        region.lon_range.maximum = phys.ParametricValue((rear_m + params.vehicle_length) / road_m)
        o.occupied_regions.append(region)
        s = o.state
        s.yaw, s.steering_angle, s.yaw_rate = phys.Angle(0.0), phys.Angle(0.0), phys.AngularVelocity(0.0)
        s.dimension.length = phys.Distance(params.vehicle_length)
        s.dimension.width = phys.Distance(params.vehicle_width)
        s.center_point.x, s.center_point.y = phys.Distance(rear_m + 0.5 * params.vehicle_length), phys.Distance(0.0)
        s.speed_range.minimum = s.speed_range.maximum = phys.Speed(v)
        return o

    ego_rear = 0.5 * road_m
    other_rear = ego_rear + (params.vehicle_length + gap_m if gap_m >= 0 else gap_m - params.vehicle_length)
    constellation = world.Constellation()
    constellation.constellation_type = world.ConstellationType.SameDirection
    constellation.ego_vehicle = vehicle(0, world.ObjectType.EgoVehicle, ego_v, ego_rear)
    constellation.object = vehicle(object_id, world.ObjectType.OtherVehicle, other_v, other_rear)
    lane = world.LaneSegment()
    lane.id = 0
    lane.length.minimum = lane.length.maximum = phys.Distance(road_m)
    lane.width.minimum = lane.width.maximum = phys.Distance(lane_w)
    lane.type = world.Normal
    lane.driving_direction = world.LaneDrivingDirection.Positive
    segment = world.RoadSegment()
    segment.type = world.RoadSegmentType.Normal
    segment.lane_segments.append(lane)
    segment.minimum_length_after_intersecting_area = segment.minimum_length_before_intersecting_area = phys.Distance(0)
    constellation.ego_vehicle_road.append(segment)
    constellation.ego_vehicle_rss_dynamics = dynamics(rss, rss.response_time_ego)
    constellation.object_rss_dynamics = dynamics(rss, rss.response_time_other,
                                                 brake_max_other if gap_m >= 0 else None)  # fmt: skip
    model = world.WorldModel()
    model.time_index = time_index
    model.default_ego_vehicle_rss_dynamics = dynamics(rss, rss.response_time_ego)
    model.constellations.append(constellation)
    return model


def full_check(checker, model) -> bool:
    """ad-rss's full check of ``model`` with ``checker`` (an ``ad_rss.rss.core.RssCheck``): the proper response's
    ``is_safe``."""
    ad_rss = _modules()[0]
    response = ad_rss.rss.state.ProperResponse()
    if not checker.calculateProperResponse(model, response):
        raise ValueError("ad-rss's RssCheck rejected the world model (see its log)")
    return bool(response.is_safe)
