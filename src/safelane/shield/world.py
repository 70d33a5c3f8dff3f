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
  lane (−1) also counts in the ego's lane (rule 4: it may enter it ahead at RSS's distance whenever it likes), and
  one whose body is in the lane beyond the target lane (2) *and ahead of the ego* counts in the target lane (rule 5,
  :func:`beyond_target`);
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
from ..baselines.rss import RssParams, stated_braking_lateral
from ..params import Params
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


def beyond_target(others: Others, prm: Params) -> np.ndarray:
    """``(B, K)``: rule 5's vehicles — non-connected, body in the lane beyond the target lane (2). :func:`roles`
    counts those ahead of the ego in the target lane, virtually. Found by the multi-lane falsifier: such a vehicle may
    enter the target lane ahead of a straddling ego at RSS's distance (legal: RSS's rear vehicle can brake) and brake,
    while the ego's evasion accelerates away from an aggressive F and passes it inside ``p_m`` with its body still in
    the target lane. Behind the ego it plays no part: there it would enter as the rear vehicle, responsible for the
    distance."""
    return ~others.connected & _body_in(others, prm, 2) & np.isfinite(others.x)


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
    # 4. the lane beside the ego's lane: a non-connected vehicle whose body is there counts in the ego's lane (it may
    # enter it ahead of the ego at RSS's distance at any time, when the ego's evasion may not be able to brake)
    inside[..., 0] |= free & _body_in(o, prm, -1)
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


def _window_min(got, valid, n_new, keep):
    """The first non-connected slot ``n_new`` of a merged, sorted lane as the vehicles it cannot hide: its speed
    becomes the lowest of the slots from it up to and including the first vehicle *physically* in the lane (a
    vehicle counted by its reach or announcement alone is not there to shield the ones ahead; docs/safety.md).
    Positions are sorted, so the slot's position is already the lowest. ``keep``: the payload keys to combine
    (speed by its minimum, an error bound by its maximum)."""
    slots = np.arange(valid.shape[1])[None, :]
    later = valid & got["phys"] & (slots >= n_new[:, None])
    first_phys = np.where(later.any(1), np.argmax(later, axis=1), valid.shape[1] - 1)
    window = valid & (slots >= n_new[:, None]) & (slots <= first_phys[:, None])
    rows = np.arange(valid.shape[0])
    at = np.minimum(n_new, valid.shape[1] - 1)
    got["v"][rows, at] = np.where(window.any(1), np.where(window, got["v"], np.inf).min(1), got["v"][rows, at])
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
    inside[..., 1] |= beyond_target(o, params) & ahead  # rule 5
    target_ahead, target_behind = inside[..., 1] & ahead, inside[..., 1] & ~ahead
    own_ahead = inside[..., 0] & ahead
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
        keys = np.concatenate([np.where(keep, s.chain_x, np.inf), np.where(target_ahead, o.x, np.inf)], axis=1)
        k = o.x.shape[1]
        payload = {
            "x": np.concatenate([s.chain_x, o.x], 1), "v": np.concatenate([s.chain_v, o.vx], 1),
            "promise": np.concatenate([_with_column(s.chain_promise, 0.0), np.zeros((b, k))], 1),
            "human": np.concatenate([_with_column(s.chain_human, False, bool), np.zeros((b, k), bool)], 1),
            "phys": np.concatenate([np.ones((b, m), bool), body[..., 1]], 1),
        }  # fmt: skip
        if s.err_chain is not None:
            payload["err"] = np.concatenate([s.err_chain, np.broadcast_to(loose[:, None, :], (b, k, 2))], 1)
        conn = np.concatenate([slots < s.n_connected[:, None], np.zeros((b, k), bool)], axis=1)
        got, valid, n_new = _merge(keys, payload, conn, m + k)
        got = {name: a[:, :m] for name, a in _window_min(got, valid, n_new, payload).items()}
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
        keys = np.concatenate([np.where(keep, own_x, np.inf), np.where(own_ahead, o.x, np.inf)], axis=1)
        payload = {
            "x": np.concatenate([own_x, o.x], 1), "v": np.concatenate([own_v, o.vx], 1),
            "promise": np.concatenate([_with_column(own_promise, 0.0), np.zeros((b, k))], 1),
            "phys": np.concatenate([np.ones((b, kk), bool), body[..., 0]], 1),
        }  # fmt: skip
        if err_own is not None:
            payload["err"] = np.concatenate([err_own, np.broadcast_to(loose[:, None, :], (b, k, 2))], 1)
        conn = np.concatenate([slots < own_n[:, None], np.zeros((b, k), bool)], axis=1)
        got, valid, n_new = _merge(keys, payload, conn, kk + k)
        got = _window_min(got, valid, n_new, payload)
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
