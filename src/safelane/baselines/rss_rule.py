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

from .._motion import advance
from ..params import Params
from .rss import pair_check, rss_params_for


class RssRule:
    """The rule with a registered RSS parameter set (``"ad_rss"``: ad-rss's documented defaults; ``"matched"``:
    this world's limits)."""

    def __init__(self, parameter_set: str):
        self.parameter_set = parameter_set

    def __repr__(self) -> str:
        return f"RssRule({self.parameter_set!r})"

    def brake_max(self, inp, params: Params):
        """``(k, M)``: each chain vehicle's ``brake_max`` — RSS's, or with V2X (``uses_chain``) a connected leader's
        bound from the chain analysis (L1's as the variant's worst case gives it)."""
        rss = rss_params_for(self.parameter_set, params)
        m = inp.chain_x.shape[1]
        bounds = np.full(inp.chain_x.shape, rss.brake_max)
        cols = min(m, inp.chain_bounds.shape[1])
        bounds[:, :cols] = inp.chain_bounds[:, :cols]
        connected = np.arange(m)[None, :] < inp.n_connected[:, None]
        out = np.where(inp.uses_chain[:, None] & connected, bounds, rss.brake_max)
        out[:, 0] = np.where(inp.uses_chain, inp.l1_decel, rss.brake_max)
        return np.maximum(out, 1e-9)

    def safe_after(self, inp, a_x, a_y, params: Params):
        """After one period of ``(a_x, a_y)``: ``(safe towards every vehicle ahead — the target lane's and, until the
        change completes, the own lane's L0 —, safe towards F, longitudinally safe towards every vehicle ahead)``,
        each ``(k,)``.

        The others are predicted at the worst RSS allows them over the period (the chain braking at its
        ``brake_max``, F accelerating at ``accel_max``), so the state checked is RSS-safe whatever they do within
        RSS's assumptions. Every chain vehicle is checked, not only L1: straddling the lane line (laterally safe) the
        ego may drive past L1."""
        rss = rss_params_for(self.parameter_set, params)
        dt = params.dt
        ex, evx = advance(inp.ego_x, inp.ego_vx, a_x, dt)
        ey = inp.ego_y + inp.ego_vy * dt + 0.5 * a_y * dt * dt
        evy = inp.ego_vy + a_y * dt
        brake = self.brake_max(inp, params)
        cx, cv = advance(inp.chain_x, inp.chain_v, -brake, dt)
        fx, fv = advance(inp.f_x, inp.f_v, rss.accel_max, dt)
        lane = params.lane_width
        with np.errstate(all="ignore"):
            col = (ex[:, None], ey[:, None], evx[:, None], evy[:, None])
            chain = pair_check(*col, cx, lane, cv, 0.0, rss, params, brake)
            to_f = pair_check(ex, ey, evx, evy, fx, lane, fv, 0.0, rss, params)
        ahead = cx > ex[:, None]
        ok_ahead, lon_ok = chain[0].all(1), (chain[1] | ~ahead).all(1)
        if inp.own_x is not None:  # L0 in the own lane (y = 0), braking at brake_max, until the change completes
            has = np.isfinite(inp.own_x) & ~inp.completed
            ox, ov = advance(np.where(has, inp.own_x, ex), np.where(has, inp.own_v, 0.0), -rss.brake_max, dt)
            with np.errstate(all="ignore"):
                own = pair_check(ex, ey, evx, evy, ox, 0.0, ov, 0.0, rss, params)
            ok_ahead &= ~has | own[0]
            lon_ok &= ~has | own[1] | ~(ox > ex)
        return ok_ahead, to_f[0], lon_ok

    def decide(self, inp, params: Params):
        """``(proceed, hesitate, respond, a_x, a_y, completing)`` for the rule's rows (see the module docstring;
        rows in none of the three are complete: following)."""
        rss = rss_params_for(self.parameter_set, params)
        dt = params.dt
        a_x, a_y = inp.a_x.copy(), inp.a_y.copy()
        active = ~inp.completed

        ok_chain, ok_f, _ = self.safe_after(inp, a_x, a_y, params)
        proceed = active & ~inp.invalid & ok_chain & ok_f
        ok_chain_h, ok_f_h, _ = self.safe_after(inp, a_x, inp.a_y_hesitate, params)
        hesitate = active & ~proceed & ok_chain_h & ok_f_h
        respond = active & ~proceed & ~hesitate
        a_y = np.where(hesitate, inp.a_y_hesitate, a_y)

        # The proper response: lateral return, braking laterally at lat_brake_min or more while still moving out;
        # braking at brake_min or more where the distance to a vehicle ahead is longitudinally unsafe.
        back = np.clip(-0.8 * inp.ego_y - 1.6 * inp.ego_vy, -params.a_y_m, params.a_y_m)
        back = np.where(inp.ego_vy > 0.0, np.minimum(back, -min(rss.lat_brake_min, params.a_y_m)), back)
        brake = -min(rss.brake_min, params.a_x_d)
        a_y = np.where(respond, back, a_y)
        # After completion: follow the vehicles ahead by RSS, centred in the target lane.
        centre = np.clip(0.8 * (params.lane_width - inp.ego_y) - 1.6 * inp.ego_vy, -params.a_y_m, params.a_y_m)
        a_y = np.where(inp.completed, centre, a_y)
        follow = respond | inp.completed
        if follow.any():
            _, _, lon_ok = self.safe_after(inp, np.where(respond, 0.0, a_x), a_y, params)
            a_x = np.where(follow & ~lon_ok, np.minimum(a_x, brake), a_x)

        moving = proceed | hesitate
        ey_end = inp.ego_y + inp.ego_vy * dt + 0.5 * a_y * dt * dt
        completing = moving & (ey_end >= params.y_boundary)
        return proceed, hesitate, respond, a_x, a_y, completing
