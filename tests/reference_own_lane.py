"""Independent numeric reference for the evasion check with an own-lane leader ``L0`` (issue 17). Test helper.

Like :mod:`reference` (whose time-stepping helpers it uses), nothing here imports ``safelane.safety`` or reuses
its closed forms: the ego's longitudinal profile is **simulated** — constant-acceleration kinematics on substeps
between a uniform grid and the profile's event times, vehicles stopping rather than reversing — and the one
unknown of a profile, the instant where the braking ego's speed comes down to the followed leader's, is found by
**bisection** on the simulated speed difference.

A profile is given by ``(u, h, b, k)``: accelerate at ``a_x_a`` on ``[0, u]``, hold the speed on ``[u, u + h]``,
brake at ``b`` until the ego's speed meets that of the followed leader ``k`` while it still moves (``k = 0``: L0,
``k = 1``: L1, ``k = -1``: none), then follow it (brake at its deceleration while it moves, then rest); without a
meeting the ego brakes to rest. The engine's family ``G(u, k)`` is ``(u, 0, a_x_d, k)``; the broader families of
the optimality-gap measurement vary ``h`` and ``b``. The profile goes on after ``t_y_f`` (the ego ends in its own
lane behind ``L0``). With an actuation delay the profile starts after ``delay`` s of cruising (the commands in flight
at the shield's start).

Gaps (each an exact minimum over piecewise quadratics, :func:`reference.gap_minimum`):

* to ``L0`` (braking at its worst case until it stops) over ``[0, ∞)``: simulated until every vehicle has stopped
  or moves at its final speed; if the ego then still moves faster than ``L0`` the gap shrinks forever (``-inf``);
* to ``L1`` and from the worst-case ``F`` (Eq. 9: ``+a_x_a`` if aggressive, else braking at ``a_x_d`` to rest)
  over ``[t_from, T]`` (``Scene.T``: ``t_y_f``, plus the delay where there is one; ``t_from`` 0 unless given).

All arrays are 1-D over one batch axis ``(R,)``; ``params`` is a :class:`safelane.Params` (only fields read).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference import braking_acc, gap_minimum, integrate, midpoints, stop_time, time_nodes

#: Bisection iterations for the meeting instant (a bracket of seconds shrinks to ~1e-16 of its length).
MEET_ITERS = 56
#: Uniform nodes per simulated span; the event times are added, so the piecewise kinematics are exact anyway.
N_GRID = 3
#: Profiles simulated at once in a brute-force search (cache-sized chunks).
CHUNK = 8192
#: Ego speed above L0's at the end of the simulated span that counts as "still closing" (round-off of a stop).
TAIL_SPEED_TOL = 1e-9


@dataclass(frozen=True)
class Profile:
    """One longitudinal evasion profile per row (see the module docstring). ``delay``: the profile starts after
    cruising for this long (the commands in flight of an actuation delay: the ego keeps its speed); the phases'
    durations ``u``, ``h`` count from there."""

    u: np.ndarray
    h: np.ndarray
    b: np.ndarray
    k: np.ndarray  # 0: follow L0, 1: follow L1, -1: follow nobody
    delay: np.ndarray | float = 0.0


@dataclass(frozen=True)
class Scene:
    """Per row: the ego's longitudinal state, ``L1``, ``L0``, ``F`` and the lateral horizon ``T = t_y_f``."""

    ego_p: np.ndarray
    ego_v: np.ndarray
    l1_p: np.ndarray
    l1_v: np.ndarray
    l1_a: np.ndarray
    l0_p: np.ndarray
    l0_v: np.ndarray
    l0_a: np.ndarray
    f_p: np.ndarray
    f_v: np.ndarray
    f_aggr: np.ndarray
    T: np.ndarray

    def take(self, idx) -> Scene:
        return Scene(**{k: getattr(self, k)[idx] for k in self.__dataclass_fields__})

    def repeat(self, n: int) -> Scene:
        """Each row ``n`` times in a row (row-major: row ``i`` occupies ``[i n, (i + 1) n)``)."""
        return Scene(**{k: np.repeat(getattr(self, k), n) for k in self.__dataclass_fields__})


def _speed_at(v, a, t):
    """Speed after ``t`` of a vehicle braking at ``a`` from ``v`` (rest afterwards)."""
    return np.maximum(v - a * t, 0.0)


def _events(scene: Scene, prof: Profile, params):
    """``(brake_start, brake_end, match, lead_stop)``: the profile's event times (the meeting by bisection)."""
    a_a = params.a_x_a
    follow0 = prof.k == 0
    lead_v = np.where(follow0, scene.l0_v, scene.l1_v)
    lead_a = np.where(follow0, scene.l0_a, scene.l1_a)
    s = prof.delay + prof.u + prof.h
    big_v = scene.ego_v + a_a * prof.u
    ego_stop = s + big_v / prof.b

    def excess(t):  # ego speed minus the followed leader's while the ego brakes from s
        return _speed_at(big_v, prof.b, t - s) - _speed_at(lead_v, lead_a, t)

    faster = excess(s) >= 0.0
    lo, hi = s.copy(), ego_stop.copy()
    for _ in range(MEET_ITERS):
        mid = 0.5 * (lo + hi)
        down = excess(mid) <= 0.0
        hi = np.where(down, mid, hi)
        lo = np.where(down, lo, mid)
    t_meet = np.where(excess(s) <= 0.0, s, hi)
    moving = _speed_at(lead_v, lead_a, t_meet) > 0.0
    match = (prof.k >= 0) & faster & moving
    lead_stop = stop_time(lead_v, lead_a)
    return s, np.where(match, t_meet, ego_stop), match, lead_stop, lead_a


def _ego_acc(mid, prof: Profile, s, brake_end, match, lead_stop, lead_a, params):
    col = lambda x: np.asarray(x, float)[:, None]  # noqa: E731
    follow = np.where(match[:, None] & (mid < col(lead_stop)), -col(lead_a), 0.0)
    start = col(np.broadcast_to(prof.delay, s.shape))
    return np.where(
        mid < start,
        0.0,
        np.where(
            mid < start + col(prof.u),
            params.a_x_a,
            np.where(mid < col(s), 0.0, np.where(mid < col(brake_end), -col(prof.b), follow)),
        ),
    )


@dataclass(frozen=True)
class Gaps:
    """Exact gap minima (not minus any margin): ``own`` over ``[0, ∞)``, ``l1`` and ``f`` over ``[t_from, T]``."""

    own: np.ndarray
    l1: np.ndarray
    f: np.ndarray


def profile_gaps(scene: Scene, prof: Profile, params, n_grid: int = N_GRID, t_from=0.0) -> Gaps:
    """Simulate the ego on ``prof`` with every other vehicle at its worst case and return the gap minima (to L1 and
    F over ``[t_from, T]``, ``t_from`` per row or scalar)."""
    a_d = params.a_x_d
    s, brake_end, match, lead_stop, lead_a = _events(scene, prof, params)
    l0_stop = stop_time(scene.l0_v, scene.l0_a)
    l1_stop = stop_time(scene.l1_v, scene.l1_a)
    f_stop = np.where(scene.f_aggr, np.inf, stop_time(scene.f_v, np.full(scene.f_v.shape, a_d)))
    t_from = np.broadcast_to(np.asarray(t_from, float), s.shape)
    start = np.broadcast_to(np.asarray(prof.delay, float), s.shape)
    follow_end = np.where(match, lead_stop, brake_end)
    events = [start, start + prof.u, s, brake_end, t_from, follow_end, l0_stop, l1_stop, f_stop, scene.T]

    def run(t_end):
        nodes = time_nodes(t_end, [np.where(np.isfinite(e), e, 0.0) for e in events], n_grid)
        mid = midpoints(nodes)
        a_e = _ego_acc(mid, prof, s, brake_end, match, lead_stop, lead_a, params)
        ego = (*integrate(nodes, scene.ego_p, scene.ego_v, a_e), a_e)
        return nodes, mid, ego

    # [0, T]: L1 and F.
    nodes, mid, ego = run(scene.T)
    a_1 = braking_acc(mid, scene.l1_a, l1_stop)
    l1 = (*integrate(nodes, scene.l1_p, scene.l1_v, a_1), a_1)
    a_f = np.where(scene.f_aggr[:, None], params.a_x_a, braking_acc(mid, np.full(s.shape, a_d), f_stop))
    fol = (*integrate(nodes, scene.f_p, scene.f_v, a_f), a_f)
    g1 = windowed_gap_minimum(nodes, t_from, *l1, *ego)
    gf = windowed_gap_minimum(nodes, t_from, *ego, *fol)

    # [0, ∞) for L0: beyond the last finite event every acceleration is zero, so one more second shows the tail.
    finite = [np.where(np.isfinite(e), e, 0.0) for e in events]
    horizon = np.maximum.reduce(finite) + 1.0
    nodes, mid, ego = run(horizon)
    a_0 = braking_acc(mid, scene.l0_a, l0_stop)
    l0 = (*integrate(nodes, scene.l0_p, scene.l0_v, a_0), a_0)
    g0, _ = gap_minimum(nodes, *l0, *ego)
    closing = ego[1][:, -1] > l0[1][:, -1] + TAIL_SPEED_TOL
    return Gaps(own=np.where(closing, -np.inf, g0), l1=g1, f=gf)


def windowed_gap_minimum(nodes, t_from, p_front, v_front, a_front, p_back, v_back, a_back):
    """The exact minimum of ``p_front − p_back`` over ``[t_from, end]`` (``t_from`` one of the nodes): the logic of
    :func:`reference.gap_minimum` restricted to the nodes and substeps from ``t_from`` on."""
    g = p_front - p_back
    gd = v_front - v_back
    c = a_front - a_back
    keep = nodes >= t_from[:, None]
    vertex = keep[:, :-1] & (gd[:, :-1] < 0.0) & (gd[:, 1:] > 0.0) & (c > 0.0)
    safe_c = np.where(vertex, c, 1.0)
    g_vertex = np.where(vertex, g[:, :-1] - gd[:, :-1] ** 2 / (2.0 * safe_c), np.inf)
    return np.minimum(np.where(keep, g, np.inf).min(axis=1), g_vertex.min(axis=1))


def margins_kept(gaps: Gaps, lead_margin, follow_margin, own_margin, nothing, slack=0.0):
    """Every gap ``>= margin + slack`` (L1 and F only where there is something to evade, ``T > 0``)."""
    own_ok = gaps.own >= own_margin + slack
    return own_ok & (nothing | ((gaps.l1 >= lead_margin + slack) & (gaps.f >= follow_margin + slack)))


def family_search(scene: Scene, variants, n_u: int, params, lead_margin, follow_margin, own_margin, slack,
                  extra_u_shift=None):  # fmt: skip
    """Brute force over ``u ∈ linspace(0, T, n_u)`` × ``variants`` (a list of ``(h, b, k)``): per row, whether some
    profile keeps every margin with ``slack`` to spare. ``extra_u_shift``: per row, also require the profile with
    ``u − shift`` (clipped at 0) to keep them (see the completeness test). Returns ``(found, best)``: ``best`` the
    index into ``variants`` of a successful profile (``-1``: none)."""
    r = scene.ego_p.shape[0]
    n_var = len(variants)
    frac = np.linspace(0.0, 1.0, n_u)
    per = n_u * n_var
    big = scene.repeat(per)
    u = (scene.T[:, None, None] * frac[None, None, :] + np.zeros((r, n_var, n_u))).reshape(-1)
    h = np.broadcast_to(np.array([v[0] for v in variants])[None, :, None], (r, n_var, n_u)).reshape(-1)
    b = np.broadcast_to(np.array([v[1] for v in variants])[None, :, None], (r, n_var, n_u)).reshape(-1)
    k = np.broadcast_to(np.array([v[2] for v in variants])[None, :, None], (r, n_var, n_u)).reshape(-1)
    rep = lambda x: np.repeat(np.broadcast_to(np.asarray(x, float), (r,)), per)  # noqa: E731
    margins = (rep(lead_margin), rep(follow_margin), rep(own_margin), np.repeat(scene.T <= 0.0, per))
    shift = None if extra_u_shift is None else np.repeat(extra_u_shift, per)
    ok = np.zeros(u.shape, bool)
    for lo in range(0, u.size, CHUNK):  # chunks that fit the cache (about 3x faster than one big batch)
        c = slice(lo, lo + CHUNK)
        sc, m = big.take(c), tuple(a[c] for a in margins)
        ok[c] = margins_kept(profile_gaps(sc, Profile(u[c], h[c], b[c], k[c]), params), *m, slack)
        if shift is not None:
            u2 = np.maximum(u[c] - shift[c], 0.0)
            ok[c] &= margins_kept(profile_gaps(sc, Profile(u2, h[c], b[c], k[c]), params), *m, slack)
    ok = ok.reshape(r, n_var, n_u)
    found = ok.any(axis=(1, 2))
    best = np.where(found, np.argmax(ok.any(axis=2), axis=1), -1)
    return found, best


def g_variants(params):
    """The engine's family ``G``: ``(h = 0, b = a_x_d, k)`` for ``k ∈ {L1, L0}``."""
    return [(0.0, params.a_x_d, 1), (0.0, params.a_x_d, 0)]


def broad_variants(params):
    """A broader piecewise-constant family containing ``G``: softer braking (``0.75``, ``0.5`` of ``a_x_d``) with or
    without following, and holding the speed for ``0.5``, ``1`` or ``2`` s before braking at ``a_x_d``."""
    a_d = params.a_x_d
    out = [(0.0, f * a_d, k) for f in (1.0, 0.75, 0.5) for k in (1, 0, -1)]
    out += [(h, a_d, k) for h in (0.5, 1.0, 2.0) for k in (1, 0, -1)]
    return out
