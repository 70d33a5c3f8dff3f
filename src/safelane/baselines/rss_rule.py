"""The RSS lane-change rule: what an AV engineer would put in front of the nominal planner instead of this paper's
shield (registered as the shield's decision rules ``rss`` and ``rss_matched``; :mod:`safelane.shield.rules`).

Every control period, for the rows of an RSS variant:

1. **proceed** if, after applying the proposal for one period, the ego is RSS-safe towards L1, towards F and,
   where the own lane has a leader L0 (``RuleInputs.own_x``), towards L0 until the change completes: for each of
   them the longitudinal safe distance holds (towards L1 and L0 with the ego behind, towards F with the ego in
   front) *or* the lateral safe distance does (:func:`.rss.pair_check`; the others predicted at the worst RSS
   allows them over the period: L1 and L0 braking at their ``brake_max``, F accelerating at ``accel_max``);
2. **hesitate** (the lateral speed driven to zero) if that is RSS-safe instead;
3. otherwise RSS's **proper response** (counted as an abort): lateral return towards the original lane, braking
   laterally at least at ``lat_brake_min`` while still moving out, and, when the longitudinal distance to L1 or L0
   (ahead) is unsafe, braking at ``brake_min`` or more. (Before L0 was checked, the rule let the ego run into its
   own lane's leader: on stock ``highway-v0`` 6 of the first 16 episodes crashed into L0.)

Once the lane change is complete (the ego's centre across the boundary) the ego follows L1 by RSS: the proposal while
the longitudinal safe distance holds after the period, braking at ``brake_min`` or more otherwise; laterally it
centres in the target lane (the paper shield's controller).

What RSS assumes and this paper does not: every other vehicle responds properly — a rear vehicle (F) brakes at
``brake_min`` at the latest after its response time, a front vehicle (L1) brakes at no more than ``brake_max``. With
V2X (``RSS_V2X``) L1's ``brake_max`` is its worst-case deceleration from the connected chain (Eqs. 1-3), which the
chain's promises guarantee. F is never connected to RSS: an aggressive F, or one that ignores the ego, breaks RSS's
assumption, and a rear-end is then, by RSS's blame rule, F's fault — the simulator counts it as a collision.
"""

from __future__ import annotations

import numpy as np

from .._motion import advance_core
from ..params import Params
from ..safety._backend import ARRAY, jitable
from .rss import pair_core, rss_params_for

#: The least ``brake_max`` a vehicle ahead is given (a bound of 0 would make RSS's stopping distance infinite).
BRAKE_FLOOR_MPS2 = 1e-9


# The rule's closed forms, written once against the backend ``xp``: :class:`RssRule` evaluates them on the rows'
# arrays, the shield's compiled period (``baselines/_fast_rss.py``) on each row's floats.


def chain_brake_core(xp, slot, uses_chain, n_connected, bound, l1_decel, brake_max):
    """RSS's ``brake_max`` of the chain's vehicle in ``slot`` (0: L1): RSS's own, or with V2X (``uses_chain``) a
    connected leader's bound from the chain analysis (``bound``), L1's the variant's worst case (``l1_decel``)."""
    out = xp.where(uses_chain & (slot < n_connected), bound, brake_max)
    out = xp.where(slot == 0, xp.where(uses_chain, l1_decel, brake_max), out)
    return xp.maximum(out, BRAKE_FLOOR_MPS2)


def ego_after_core(xp, ego_x, ego_y, ego_vx, ego_vy, a_x, a_y, dt):
    """The ego after one period of ``(a_x, a_y)`` (longitudinally stopping at rest): ``(x, y, vx, vy)``."""
    ex, evx = advance_core(xp, ego_x, ego_vx, a_x, dt)
    return ex, ego_y + ego_vy * dt + 0.5 * a_y * dt * dt, evx, ego_vy + a_y * dt


def ahead_after_core(xp, ex, ey, evx, evy, x, v, y, brake, rss, length, width, dt):
    """One vehicle ahead (a chain vehicle at ``y``, or L0), predicted braking at ``brake`` (its ``brake_max``) over the
    period, against the ego after it (``ex, ey, evx, evy``): ``(safe, longitudinally safe or not ahead)``."""
    x1, v1 = advance_core(xp, x, v, -brake, dt)
    checked = pair_core(xp, ex, ey, evx, evy, x1, y, v1, 0.0, rss, length, width, brake)
    return checked[0], xp.where(x1 > ex, checked[1], True)


def follower_after_core(xp, ex, ey, evx, evy, f_x, f_v, y, rss, length, width, dt):
    """F, predicted accelerating at ``accel_max`` over the period, against the ego after it: safe."""
    x1, v1 = advance_core(xp, f_x, f_v, rss.accel_max, dt)
    return pair_core(xp, ex, ey, evx, evy, x1, y, v1, 0.0, rss, length, width, rss.brake_max)[0]


def verdict_core(xp, active, invalid, ok_chain, ok_f, ok_chain_h, ok_f_h):
    """``(proceed, hesitate, respond)``: the proposal where it is RSS-safe after the period (never an invalid one),
    else the hesitation where that is, else RSS's proper response; none of them once the change is complete."""
    proceed = active & xp.where(invalid, False, ok_chain & ok_f)
    hesitate = active & xp.where(proceed, False, ok_chain_h & ok_f_h)
    return proceed, hesitate, active & xp.where(proceed | hesitate, False, True)


def lateral_core(xp, proceed, hesitate, respond, completed, a_y, a_y_hesitate, a_y_keep, ego_y, ego_vy, a_y_m,
                 lat_brake_min):  # fmt: skip
    """The lateral command: the proposal, the hesitation, the proper response (back towards the original lane,
    braking laterally at ``lat_brake_min`` or more while still moving out), or after completion the lane keeping
    ``a_y_keep`` (the paper shield's controller)."""
    back = xp.clip(-0.8 * ego_y - 1.6 * ego_vy, -a_y_m, a_y_m)
    back = xp.where(ego_vy > 0.0, xp.minimum(back, -xp.minimum(lat_brake_min, a_y_m)), back)
    out = xp.where(hesitate, a_y_hesitate, a_y)
    out = xp.where(respond, back, out)
    return xp.where(completed, a_y_keep, out)


def follow_check_accel(xp, respond, a_x):
    """The longitudinal acceleration a following row's check assumes over the period: none while responding (the
    response may brake), else the proposal."""
    return xp.where(respond, 0.0, a_x)


def follow_core(xp, follow, lon_ok, a_x, brake_min, a_x_d):
    """The longitudinal command of a following row (responding or complete): the proposal while the longitudinal
    safe distance to every vehicle ahead holds after the period (``lon_ok``, checked at
    :func:`follow_check_accel`), else braking at ``brake_min`` (at most the ego's ``a_x_d``) or more."""
    return xp.where(follow & xp.where(lon_ok, False, True), xp.minimum(a_x, -xp.minimum(brake_min, a_x_d)), a_x)


def completing_core(xp, proceed, hesitate, ego_y, ego_vy, a_y, dt, y_boundary):
    """Whether a moving row's centre crosses the lane boundary this period."""
    return (proceed | hesitate) & (ego_y + ego_vy * dt + 0.5 * a_y * dt * dt >= y_boundary)


class RssRule:
    """The rule with a registered RSS parameter set (``"ad_rss"``: ad-rss's documented defaults; ``"matched"``:
    this world's limits)."""

    def __init__(self, parameter_set: str):
        self.parameter_set = parameter_set

    def __repr__(self) -> str:
        return f"RssRule({self.parameter_set!r})"

    def params(self, params: Params):
        """The :class:`~.rss.RssParams` of this rule in the world ``params``."""
        return rss_params_for(self.parameter_set, params)

    def brake_max(self, inp, params: Params):
        """``(k, M)``: each chain vehicle's ``brake_max`` (:func:`chain_brake_core`)."""
        rss = self.params(params)
        m = inp.chain_x.shape[1]
        bounds = np.full(inp.chain_x.shape, rss.brake_max)
        cols = min(m, inp.chain_bounds.shape[1])
        bounds[:, :cols] = inp.chain_bounds[:, :cols]
        return chain_brake_core(ARRAY, np.arange(m)[None, :], inp.uses_chain[:, None], inp.n_connected[:, None],
                                bounds, inp.l1_decel[:, None], rss.brake_max)  # fmt: skip

    def safe_after(self, inp, a_x, a_y, params: Params):
        """After one period of ``(a_x, a_y)``: ``(safe towards every vehicle ahead — the target lane's and, until the
        change completes, the own lane's L0 —, safe towards F, longitudinally safe towards every vehicle ahead)``,
        each ``(k,)``.

        The others are predicted at the worst RSS allows them over the period (the chain braking at its
        ``brake_max``, F accelerating at ``accel_max``), so the state checked is RSS-safe whatever they do within
        RSS's assumptions. Every chain vehicle is checked, not only L1: straddling the lane line (laterally safe) the
        ego may drive past L1."""
        rss = self.params(params)
        length, width, lane = params.vehicle_length, params.vehicle_width, params.lane_width
        with np.errstate(all="ignore"):
            ex, ey, evx, evy = ego_after_core(ARRAY, inp.ego_x, inp.ego_y, inp.ego_vx, inp.ego_vy, a_x, a_y, params.dt)
            col = (ex[:, None], ey[:, None], evx[:, None], evy[:, None])
            safe, lon_ok = ahead_after_core(ARRAY, *col, inp.chain_x, inp.chain_v, lane, self.brake_max(inp, params),
                                            rss, length, width, params.dt)  # fmt: skip
            to_f = follower_after_core(ARRAY, ex, ey, evx, evy, inp.f_x, inp.f_v, lane, rss, length, width, params.dt)
        ok_ahead, lon_ok = safe.all(1), lon_ok.all(1)
        if inp.own_x is not None:  # L0 in the own lane (y = 0), braking at brake_max, until the change completes
            has = np.isfinite(inp.own_x) & ~inp.completed
            with np.errstate(all="ignore"):
                own_safe, own_lon = ahead_after_core(ARRAY, ex, ey, evx, evy, np.where(has, inp.own_x, ex),
                                                     np.where(has, inp.own_v, 0.0), 0.0, rss.brake_max, rss, length,
                                                     width, params.dt)  # fmt: skip
            ok_ahead &= ~has | own_safe
            lon_ok &= ~has | own_lon
        return ok_ahead, to_f, lon_ok

    def decide(self, inp, params: Params):
        """``(proceed, hesitate, respond, a_x, a_y, completing)`` for the rule's rows (see the module docstring;
        rows in none of the three are complete: following)."""
        rss = self.params(params)
        ok_chain, ok_f, _ = self.safe_after(inp, inp.a_x, inp.a_y, params)
        ok_chain_h, ok_f_h, _ = self.safe_after(inp, inp.a_x, inp.a_y_hesitate, params)
        proceed, hesitate, respond = verdict_core(ARRAY, ~inp.completed, inp.invalid, ok_chain, ok_f, ok_chain_h,
                                                  ok_f_h)  # fmt: skip
        a_y = lateral_core(ARRAY, proceed, hesitate, respond, inp.completed, inp.a_y, inp.a_y_hesitate, inp.a_y_keep,
                           inp.ego_y, inp.ego_vy, params.a_y_m, rss.lat_brake_min)  # fmt: skip
        a_x = inp.a_x
        follow = respond | inp.completed
        if follow.any():
            _, _, lon_ok = self.safe_after(inp, follow_check_accel(ARRAY, respond, a_x), a_y, params)
            a_x = follow_core(ARRAY, follow, lon_ok, a_x, rss.brake_min, params.a_x_d)
        completing = completing_core(ARRAY, proceed, hesitate, inp.ego_y, inp.ego_vy, a_y, params.dt,
                                     params.y_boundary)  # fmt: skip
        return proceed, hesitate, respond, a_x, a_y, completing


jitable(chain_brake_core, ego_after_core, ahead_after_core, follower_after_core, verdict_core, lateral_core,
        follow_check_accel, follow_core, completing_core)
