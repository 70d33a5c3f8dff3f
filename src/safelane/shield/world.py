"""The world model: the vehicles besides F, the target-lane chain and L0 that can enter the ego's path, folded into
the paper's roles (docs/safety.md, "Other vehicles' lane changes").

A :class:`Others` record carries them, ``(B, K)`` arrays in the shield's frame: ``x`` along the road, ``y`` the
lateral position of the centre from the original lane's centre, positive toward the target lane — lane ``i``'s
centre at ``y = i · lane_width`` (lane 0 the ego's original lane, 1 the target lane, 2 the lane beyond it, −1 the
lane on the ego's other side). A row's unused slots are padding: ``x = +inf``.

:func:`roles` is the one place the others are read. It decides, per vehicle, in which of the two lanes that matter
(0 and 1) it counts, and then folds it into the roles the analysis knows:

* **lanes**: a vehicle counts in every lane its body overlaps (a straddler in both); a *non-connected* one also in
  every lane its RSS lateral worst case reaches — lateral acceleration toward the lane at ``lat_accel_max`` for its
  response time ρ, then lateral braking at ``lat_brake_min`` to zero lateral speed, plus RSS's fluctuation margin
  μ/2 (:func:`~safelane.baselines.rss.stated_braking_lateral`; parameters :meth:`RssParams.matched
  <safelane.baselines.rss.RssParams.matched>` unless given, as the blame rule uses them); a *connected* one is
  trusted to stay in the lanes its body overlaps until it announces a lane change over V2X, and counts in the
  announced lane from ``announce_t − horizon_s`` on; a *non-connected* one whose body is in the lane beside the ego's
  lane (−1) or beyond the target lane (2) also counts ahead of the ego in the lane next to it (rules 4 and 5: it may
  enter there at RSS's distance whenever it likes), at its own state or at the cut-in bound (:func:`entrants`);
* **target lane, ahead of the ego** (``x > ego_x``): merged into the chain by position; each is non-connected (the
  record carries no braking promise), so the connected chain ends at the first of them (N shrinks);
* **target lane, behind the ego**: the nearest becomes F where it is nearer than F — non-connected, not
  collaborative, and the aggressiveness assessment of that row starts afresh (:func:`fold`);
* **own lane, ahead of the ego**: merged into the own-lane leaders (``own_x``), ``L0`` first; non-connected, so the
  own lane's connected chain ends at the first of them.

Vehicles behind the ego in its own lane, and in lanes other than 0 and 1 whose worst case reaches neither, play no
role (RSS: a rear vehicle in the ego's lane is responsible for its distance). The record must not repeat F, the
chain or L0 (a repeated vehicle would be merged next to itself: a link with no gap, which the chain analysis takes
for unsafe).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._motion import advance
from ..baselines.rss import (
    RssParams,
    longitudinal_safe_distance_exact,
    stated_braking_lateral,
    stated_braking_longitudinal,
)
from ..params import Params
from ..safety.lateral import lateral_core
from .monitor import TOL_M
from .others import NO_LANE, Others
from .policies import ASSESSMENTS

#: Default ``horizon_s``: how long before its announced start a connected vehicle counts in the announced lane [s].
#: It must cover the longest evasion plan the shield holds (docs/safety.md).
ANNOUNCE_HORIZON_S = 10.0
#: Spacing of the padding slots beyond ``L(N+1)`` after a merge [m] (far ahead: links there are never binding).
PAD_M = 1.0e4
#: The lanes that have roles: the ego's original lane (0) and the target lane (1).
ROLE_LANES = (0, 1)

def body_lanes(others: Others, prm: Params) -> np.ndarray:
    """``(B, K, 2)``: whether each vehicle's body overlaps lane 0 and lane 1 now (rule 1 alone: the vehicle is
    *physically* in the lane; padding is in none)."""
    half = 0.5 * prm.vehicle_width
    return _overlaps(others.y - half, others.y + half, prm) & np.isfinite(others.x)[..., None]


def _overlaps(lo, hi, prm: Params) -> np.ndarray:
    """``(B, K, 2)``: whether the lateral extent ``(lo, hi)`` (``(B, K)``) overlaps lane 0 and lane 1."""
    lanes = np.asarray(ROLE_LANES, float)
    return (hi[..., None] > (lanes - 0.5) * prm.lane_width) & (lo[..., None] < (lanes + 0.5) * prm.lane_width)


def dilemma_s(situation, prm: Params) -> np.ndarray:
    """``(B,)`` how long the evasion adopted this period can keep the ego's body in the target lane [s]: the fastest
    lateral return to ``y_s`` (Eq. 5) from the farthest lateral state one period of ``a_y_m`` toward the target lane
    can reach, plus one period. While the body is in the target lane an aggressive ``F`` may oblige the evasion to
    accelerate; afterwards the ego can always brake (rule 4)."""
    a, dt = prm.a_y_m, prm.dt
    y = situation.ego_y + situation.ego_vy * dt + 0.5 * a * dt * dt
    with np.errstate(invalid="ignore"):
        t_back = lateral_core(np, y, situation.ego_vy + a * dt, prm)[0]
    return t_back + dt


def entrants(situation, others: Others, prm: Params):
    """Rules 4 and 5: the non-connected vehicles whose body is in lane −1, beside the ego's lane (rule 4), or in lane 2,
    beyond the target lane (rule 5), as leaders in the lane next to theirs (0 or 1). Returns ``(x, v, counted)``, each
    ``(B, K)``: the state each counts at there and whether it counts (one pass for both lanes: the bound does not
    depend on the lane).

    RSS lets such a vehicle enter that lane ahead of the ego whenever it is at RSS's safe distance plus ``p_m`` (the
    ego the rear vehicle: one period at ``a_x_a``, then ``a_x_d``; the entrant brakes at ``a_o_d``) — and then brake,
    when an ego escaping an aggressive ``F`` may be unable to. So:

    * **at that distance now**: it counts at its own state (its braking from now bounds every trajectory it has);
    * **not yet, but able to reach ``p_m`` ahead of the ego within** :func:`dilemma_s` (it accelerating at ``a_x_a``,
      the ego braking at ``a_x_d``): it counts at the **cut-in bound** ``(ego_x + p_m, v*)``, ``v*² = 2·a_o_d·S``
      with ``S`` the ego's RSS stopping distance — every legal entry's braking trajectory lies ahead of this one
      (docs/safety.md, rule 4), whenever it happens;
    * otherwise it plays no role: it cannot enter ahead of the ego before the evasion adopted now has taken the ego's
      body out of the target lane, and from then on the ego can brake (the bound holds it from the period it can
      reach).

    Found by the multi-lane falsifier (rule 4): a faster vehicle beside and behind the ego overtook it during an abort
    and entered at RSS's distance; counted only once ahead of the ego's centre, it came too late for any evasion."""
    o, s = others, situation
    ex, ev = s.ego_x[:, None], s.ego_vx[:, None]
    a_o, a_up, a_dn, dt = prm.others_decel, prm.a_x_a, prm.a_x_d, prm.dt
    there = ~o.connected & (_body_in(o, prm, -1) | _body_in(o, prm, 2)) & np.isfinite(o.x)
    with np.errstate(invalid="ignore"):
        gap = o.x - ex - prm.p_m
        ready = there & (gap >= longitudinal_safe_distance_exact(o.vx, ev, dt, a_up, a_dn, a_o))
        h = dilemma_s(s, prm)[:, None]
        tb = np.minimum(h, ev / a_dn)
        gained = o.vx * h + 0.5 * a_up * h * h - (ev * tb - 0.5 * a_dn * tb * tb)
    cut = there & ~ready & ((gap >= 0.0) | (gap + gained >= 0.0))
    v_star = np.sqrt(2.0 * a_o * stated_braking_longitudinal(ev, dt, a_up, a_dn))
    return np.where(cut, ex + prm.p_m, o.x), np.where(cut, v_star, o.vx), ready | cut


def _body_in(o: Others, prm: Params, lane: int) -> np.ndarray:
    """``(B, K)``: whether each vehicle's body overlaps lane ``lane``."""
    half, w = 0.5 * prm.vehicle_width, prm.lane_width
    return (o.y + half > (lane - 0.5) * w) & (o.y - half < (lane + 0.5) * w)


def lane_reach(others: Others, t: float, prm: Params, rss: RssParams | None = None,
               horizon_s: float = ANNOUNCE_HORIZON_S) -> np.ndarray:  # fmt: skip
    """``(B, K, 2)``: whether each vehicle counts in lane 0 (the ego's original lane) and lane 1 (the target lane)
    at time ``t`` (the module docstring's rule; padding counts nowhere)."""
    rss = RssParams.matched(prm) if rss is None else rss
    o = others
    rho, a_lat, b_lat = rss.response_time_other, rss.lat_accel_max, rss.lat_brake_min
    free = ~o.connected  # the RSS lateral worst case: non-connected vehicles only
    up = np.where(free, np.maximum(stated_braking_lateral(o.vy, rho, a_lat, b_lat), 0.0), 0.0)
    down = np.where(free, np.maximum(stated_braking_lateral(-o.vy, rho, a_lat, b_lat), 0.0), 0.0)
    mu = np.where(free, 0.5 * rss.lateral_fluctuation_margin, 0.0)
    half = 0.5 * prm.vehicle_width
    inside = _overlaps(o.y - half - down - mu, o.y + half + up + mu, prm)
    announced = o.connected & (o.announce_lane != NO_LANE) & (t >= o.announce_t - horizon_s)
    inside |= announced[..., None] & (o.announce_lane[..., None] == np.asarray(ROLE_LANES))
    return inside & np.isfinite(o.x)[..., None]


def _loosest(s) -> np.ndarray | None:
    """``(B, 2)`` the loosest sensing-error bound the row gives any vehicle (the bound of an inserted vehicle), or
    ``None`` where the situation has none."""
    parts = [e.reshape(len(s.ego_x), -1, 2) for e in (s.err_f, s.err_chain, s.err_own) if e is not None]
    if not parts:
        return None
    return np.concatenate(parts, axis=1).max(axis=1)


def _merge(keys, payload, conn, width: int):
    """Sort each row's vehicles by ``keys`` (``+inf``: none), keep ``width`` slots. ``payload``: ``{name: (B, J, ...)}``
    gathered alike; ``conn (B, J)``. Returns ``(gathered, valid (B, width), n_connected (B,))``: ``n_connected`` the
    leading connected vehicles (the first non-connected one ends the chain)."""
    order = np.argsort(keys, axis=1, kind="stable")[:, :width]
    take = lambda a: np.take_along_axis(a, order.reshape(order.shape + (1,) * (a.ndim - 2)), axis=1)  # noqa: E731
    valid = np.isfinite(take(keys))
    lead = np.cumprod(take(conn) & valid, axis=1).sum(1)
    return {name: take(a) for name, a in payload.items()}, valid, lead


def _fold_window(got, valid, n_new, keep, decel: float):
    """The first non-connected slot ``n_new`` of a merged, sorted lane as the vehicles it cannot hide, the slots from
    it up to and including the first vehicle *physically* in the lane (a vehicle counted by its reach, announcement
    or rule 4 alone is not there to shield the ones ahead; docs/safety.md). Positions are sorted, so the slot's
    position is already the lowest. Its speed becomes the one whose braking at ``decel`` (the others' ``a_o_d``, the
    analysis' worst case for a non-connected vehicle) stops at the nearest of their stopping points: that braking
    trajectory lies behind each of theirs at every instant (same start or behind, same deceleration, stopping no
    farther; docs/safety.md). With sensing-error bounds (``"err"`` in ``keep``) the speed is the lowest of the window
    instead (the corners of the boxes need not order alike) and the bound the largest."""
    slots = np.arange(valid.shape[1])[None, :]
    later = valid & got["phys"] & (slots >= n_new[:, None])
    first_phys = np.where(later.any(1), np.argmax(later, axis=1), valid.shape[1] - 1)
    window = valid & (slots >= n_new[:, None]) & (slots <= first_phys[:, None])
    rows = np.arange(valid.shape[0])
    at = np.minimum(n_new, valid.shape[1] - 1)
    if "err" in keep:
        combined = np.where(window, got["v"], np.inf).min(1)
    else:
        with np.errstate(invalid="ignore"):
            stop = np.where(window, got["x"] + got["v"] * got["v"] / (2.0 * decel), np.inf).min(1)
            combined = np.sqrt(np.maximum(2.0 * decel * (stop - got["x"][rows, at]), 0.0))
    got["v"][rows, at] = np.where(window.any(1), combined, got["v"][rows, at])
    if "err" in keep:
        err = np.where(window[..., None], got["err"], -np.inf).max(1)
        got["err"][rows, at] = np.where(window.any(1)[:, None], err, got["err"][rows, at])
    return got


def _with_column(a, value, dtype=None):
    """``a (B, J)`` with one more column of ``value`` (the last slot's promise/flag, which the chain does not hold)."""
    return np.concatenate([a, np.full((a.shape[0], 1), value, dtype or a.dtype)], axis=1)


def roles(situation, params: Params, rss: RssParams | None = None, horizon_s: float = ANNOUNCE_HORIZON_S):
    """The situation with its ``others`` folded into F, the chain and the own lane (module docstring), and
    ``others`` removed; a situation without ``others`` is returned as it is. Pure, batched (no loop over rows or
    vehicles)."""
    s = situation
    o = getattr(s, "others", None)
    if o is None:
        return s
    b, m = s.chain_x.shape
    inside = lane_reach(o, s.t, params, rss, horizon_s)
    body = body_lanes(o, params)
    ahead = o.x > s.ego_x[:, None]
    # each lane's vehicles ahead: at their own state (rules 1-3), or as rules 4 and 5 count them
    own_state, target_state = inside[..., 0] & ahead, inside[..., 1] & ahead
    bound_x, bound_v, counted = entrants(s, o, params)
    side, far = counted & _body_in(o, params, -1), counted & _body_in(o, params, 2)  # rules 4 and 5
    own_ahead, target_ahead = own_state | side, target_state | far
    own_cx, own_cv = np.where(own_state, o.x, bound_x), np.where(own_state, o.vx, bound_v)
    tgt_cx, tgt_cv = np.where(target_state, o.x, bound_x), np.where(target_state, o.vx, bound_v)
    target_behind = inside[..., 1] & ~ahead
    loose = _loosest(s)
    out = {"others": None}

    # F: the nearest target-lane vehicle behind the ego physically in the lane (F or an entrant), and the vehicles
    # counted there by reach or announcement alone that are nearer still: the nearest position and the highest speed
    # of them (non-connected, aggressive).
    rows = np.arange(b)
    phys_x = np.where(target_behind & body[..., 1], o.x, -np.inf).max(1)
    near_x = np.maximum(s.f_x, phys_x)
    virtual = target_behind & ~body[..., 1] & (o.x > near_x[:, None])
    phys_v = np.where(s.f_x >= phys_x, s.f_v, o.vx[rows, np.argmax(np.where(target_behind & body[..., 1], o.x,
                                                                             -np.inf), axis=1)])  # fmt: skip
    f_x_new = np.maximum(near_x, np.where(virtual, o.x, -np.inf).max(1))
    f_v_new = np.maximum(phys_v, np.where(virtual, o.vx, -np.inf).max(1))
    new_f = (f_x_new != s.f_x) | (f_v_new != s.f_v)
    if new_f.any():
        out.update(
            f_x=np.where(new_f, f_x_new, s.f_x), f_v=np.where(new_f, f_v_new, s.f_v),
            f_connected=s.f_connected & ~new_f, f_collaborative=s.f_collaborative & ~new_f,
        )  # fmt: skip
        if s.f_speed_observed is not None:
            out["f_speed_observed"] = np.where(new_f, f_v_new, s.f_speed_observed)
        if s.f_aggressive_truth is not None:
            out["f_aggressive_truth"] = s.f_aggressive_truth | new_f
        if s.err_f is not None:
            out["err_f"] = np.where(new_f[:, None], loose, s.err_f)

    # The chain: L1..L(N+1) and the entrants ahead, by position; the first non-connected one ends it.
    merge_rows = target_ahead.any(1)
    if merge_rows.any():
        slots = np.arange(m)[None, :]
        keep = slots <= s.n_connected[:, None]
        keys = np.concatenate([np.where(keep, s.chain_x, np.inf), np.where(target_ahead, tgt_cx, np.inf)], axis=1)
        k = o.x.shape[1]
        payload = {
            "x": np.concatenate([s.chain_x, tgt_cx], 1), "v": np.concatenate([s.chain_v, tgt_cv], 1),
            "promise": np.concatenate([_with_column(s.chain_promise, 0.0), np.zeros((b, k))], 1),
            "human": np.concatenate([_with_column(s.chain_human, False, bool), np.zeros((b, k), bool)], 1),
            "phys": np.concatenate([np.ones((b, m), bool), body[..., 1] & target_state], 1),
        }  # fmt: skip
        if s.err_chain is not None:
            payload["err"] = np.concatenate([s.err_chain, np.broadcast_to(loose[:, None, :], (b, k, 2))], 1)
        conn = np.concatenate([slots < s.n_connected[:, None], np.zeros((b, k), bool)], axis=1)
        got, valid, n_new = _merge(keys, payload, conn, m + k)
        got = {name: a[:, :m] for name, a in _fold_window(got, valid, n_new, payload, params.others_decel).items()}
        # Beyond the new L(N+1): padding far ahead, at its speed (links there never bind).
        last_x = np.take_along_axis(got["x"], n_new[:, None], 1)
        last_v = np.take_along_axis(got["v"], n_new[:, None], 1)
        beyond = slots > n_new[:, None]
        x_new = np.where(beyond, last_x + PAD_M * (slots - n_new[:, None]), got["x"])
        v_new = np.where(beyond, last_v, got["v"])
        rows2 = merge_rows[:, None]
        out.update(
            chain_x=np.where(rows2, x_new, s.chain_x), chain_v=np.where(rows2, v_new, s.chain_v),
            chain_promise=np.where(rows2, got["promise"][:, : m - 1], s.chain_promise),
            chain_human=np.where(rows2, got["human"][:, : m - 1], s.chain_human),
            n_connected=np.where(merge_rows, n_new, s.n_connected),
        )  # fmt: skip
        if s.err_chain is not None:
            err = np.where(beyond[..., None], 0.0, got["err"])
            out["err_chain"] = np.where(rows2[..., None], err, s.err_chain)

    # The own lane: L0 (and its connected chain) and the entrants ahead, by position.
    own_rows = own_ahead.any(1)
    if own_rows.any():
        if s.own_x is None:  # the paper's empty original lane: one slot, L0
            own_x, own_v = np.full((b, 1), np.inf), np.zeros((b, 1))
            own_promise, own_n = np.zeros((b, 0)), np.zeros(b, np.int64)
            err_own = None if loose is None else np.zeros((b, 1, 2))
        else:
            own_x, own_v, own_promise, own_n = s.own_x, s.own_v, s.own_promise, s.own_n_connected
            err_own = s.err_own if s.err_own is not None or loose is None else np.zeros((*own_x.shape, 2))
        kk, k = own_x.shape[1], o.x.shape[1]
        slots = np.arange(kk)[None, :]
        keep = (slots <= own_n[:, None]) & np.isfinite(own_x)
        keys = np.concatenate([np.where(keep, own_x, np.inf), np.where(own_ahead, own_cx, np.inf)], axis=1)
        payload = {
            "x": np.concatenate([own_x, own_cx], 1), "v": np.concatenate([own_v, own_cv], 1),
            "promise": np.concatenate([_with_column(own_promise, 0.0), np.zeros((b, k))], 1),
            "phys": np.concatenate([np.ones((b, kk), bool), body[..., 0] & own_state], 1),
        }  # fmt: skip
        if err_own is not None:
            payload["err"] = np.concatenate([err_own, np.broadcast_to(loose[:, None, :], (b, k, 2))], 1)
        conn = np.concatenate([slots < own_n[:, None], np.zeros((b, k), bool)], axis=1)
        got, valid, n_new = _merge(keys, payload, conn, kk + k)
        got = _fold_window(got, valid, n_new, payload, params.others_decel)
        got, valid = {name: a[:, :kk] for name, a in got.items()}, valid[:, :kk]
        there = valid & (slots <= n_new[:, None])  # L0 .. the first non-connected one; +inf beyond
        rows2 = own_rows[:, None]
        out.update(
            own_x=np.where(rows2, np.where(there, got["x"], np.inf), own_x),
            own_v=np.where(rows2, np.where(there, got["v"], 0.0), own_v),
            own_promise=np.where(rows2, got["promise"][:, : kk - 1], own_promise),
            own_n_connected=np.where(own_rows, n_new, own_n).astype(np.int64),
        )  # fmt: skip
        if err_own is not None:
            out["err_own"] = np.where(rows2[..., None], np.where(there[..., None], got["err"], 0.0), err_own)
    return dataclasses.replace(s, **out)


def replaced_follower(situation, folded) -> np.ndarray:
    """``(B,)`` rows whose F :func:`roles` replaced by a nearer entrant."""
    return np.asarray(folded.f_x != situation.f_x)


def follower_switched(last, folded, params: Params) -> np.ndarray:
    """``(B,)`` rows whose F is no longer the vehicle of the last period: its state now is not one that vehicle could
    reach in a period, accelerating in ``[−a_o_d, a_x_a]`` (exact, stopping at rest), widened by the sensing box
    (``err_f``) at both ends and ``TOL_M``. Found by the multi-lane falsifier: an F that a vehicle counted in the
    target lane only by its reach had replaced went back to the host's F when the reach no longer counted it, the
    assessment read the jump in speed as F yielding, and the shield took an aggressive F for collaborative. ``last``
    (the previous period's :class:`~.monitor.Snapshot`) ``None``: no row."""
    if last is None:
        return np.zeros(len(folded.f_x), bool)
    x_hi, v_hi = advance(last.f_x, last.f_v, params.a_x_a, params.dt)
    x_lo, v_lo = advance(last.f_x, last.f_v, -params.others_decel, params.dt)
    box = np.zeros((len(folded.f_x), 2)) if folded.err_f is None else 2.0 * np.asarray(folded.err_f)
    ex, ev = box[:, 0] + TOL_M, box[:, 1] + TOL_M
    x, v = folded.f_x, folded.f_v
    return (x > x_hi + ex) | (x < x_lo - ex) | (v > v_hi + ev) | (v < v_lo - ev)


def restart_rows(state, rows: np.ndarray, fresh):
    """``state`` (a dataclass of ``(B, ...)`` arrays, possibly nested) with ``rows`` taken from ``fresh``."""
    if dataclasses.is_dataclass(state):
        return dataclasses.replace(state, **{f.name: restart_rows(getattr(state, f.name), rows, getattr(fresh, f.name))
                                             for f in dataclasses.fields(state)})  # fmt: skip
    if isinstance(state, np.ndarray) and state.ndim >= 1 and state.shape[0] == rows.shape[0]:
        return np.where(rows.reshape(rows.shape + (1,) * (state.ndim - 1)), fresh, state)
    return state


def fold(state, situation, params: Params, config, chain=None):
    """``(state, situation, chain)`` as :func:`safelane.shield.stages.observe` takes them, with the others folded in
    (:func:`roles`): the aggressiveness assessment restarts where F was replaced, or where F is not the vehicle of the
    last period (:func:`follower_switched`; its history was another vehicle's; a restarted belief is "aggressive"),
    and ``chain`` (an analysis of the unfolded situation) is dropped. Without ``others`` all three are returned as
    they are."""
    if getattr(situation, "others", None) is None:
        return state, situation, chain
    folded = roles(situation, params)
    swapped = replaced_follower(situation, folded) | follower_switched(getattr(state, "last", None), folded, params)
    if swapped.any() and state.belief is not None:
        fresh = ASSESSMENTS[config.assessment].start(len(swapped), config)
        state = dataclasses.replace(state, belief=restart_rows(state.belief, swapped, fresh))
    return state, folded, None
