"""Optimality of the engine's "no evasion" verdict and soundness of its evasion plans (paper §3.3, Eq. 9).

* **No evasion means none.** For random states where :func:`plan_evasion` says no evasion exists, a vectorized
  random search over ``>= 100,000`` piecewise-constant longitudinal acceleration profiles in ``[-a_x_d, a_x_a]`` —
  the ego's committed limits — (10–30 pieces over ``[0, t_y_f]``, speed clipped at zero; the lateral return keeps
  the same ``t_y_f``) finds none that keeps both gaps — to the worst-case ``L1`` (which may brake harder than the
  ego: ``others_harder``) and the worst-case ``F`` — at least the margin on ``[0, t_y_f]``. The profiles are
  integrated exactly per substep and the gaps checked on the substep nodes, which can overestimate a gap's minimum
  by at most ``(a_x_a + a_x_d) h² / 8``; the states are therefore chosen at least ``SHORTFALL_MIN_M`` from the
  boundary (more than four times that bound), and as close to it as that allows (at most ``SHORTFALL_MAX_M``),
  where a search has the best chance.
* **The search has power.** The same search, on states the engine calls feasible with a little room, does find
  valid profiles for nearly every state — so finding none above means something.
* **Plans are sound.** Where an evasion exists, the engine's own plan (``plan.state(t)`` on a fine grid) keeps
  both gaps ``>= margin − 1e-6`` against the worst-case ``L1`` and ``F`` trajectories of the independent
  reference, moves within the acceleration limits, and is back in its lane from ``t_y_f`` on.
"""

from __future__ import annotations

import numpy as np

from reference import braked_position, follower_position
from safelane import Params
from safelane.safety import Reason, plan_evasion

PARAMS_SETS = {
    "default": Params(),
    "sluggish": Params(a_x_a=1.5, a_x_d=6.0, a_y_m=0.8, p_m=8.0, p_m_human=11.0),
    # Others brake up to 9.5 m/s², the ego commits to 6 (the realistic preset's split): L1 may brake harder than the
    # ego's evasion, which then never follows it.
    "others_harder": Params(a_x_a=2.4, a_x_d=6.0, a_o_d=9.5, a_y_m=2.9, p_m=8.9, p_m_human=10.0),
}
N_SUB = 360  # substeps per profile (a multiple of every piece count)
PIECE_COUNTS = (10, 12, 15, 20, 30)
PROFILES_PER_STATE = 2_560
N_STATES = 24  # per parameter set: 3 × 24 × 2,560 = 184,320 profiles
MIN_PROFILES = 100_000
SHORTFALL_MIN_M = 0.01
SHORTFALL_MAX_M = 1.0
GAP_TOL_M = 1e-6


# --------------------------------------------------------------------------------------------------------------
# States
# --------------------------------------------------------------------------------------------------------------


def random_states(rng: np.random.Generator, params: Params, n: int) -> dict:
    """Mid-lane-change states with L1 ahead and F behind in the target lane, tight gaps included."""
    y_s = params.y_safe
    leader_human = rng.random(n) < 0.2
    follower_human = rng.random(n) < 0.2
    lead_margin = np.where(leader_human, params.p_m_human, params.p_m)
    follow_margin = np.where(follower_human, params.p_m_human, params.p_m)
    ego_px = rng.uniform(-100.0, 100.0, n)
    return dict(
        ego_px=ego_px,
        ego_py=y_s + rng.uniform(0.0, params.lane_width - y_s, n),
        ego_vx=rng.uniform(0.0, 35.0, n),
        ego_vy=rng.uniform(-1.0, 1.5, n),
        l1_p=ego_px + lead_margin + rng.uniform(-1.0, 40.0, n),
        l1_v=rng.uniform(0.0, 35.0, n),
        l1_decel=rng.uniform(0.0, max(params.a_x_d, params.a_x_d if params.a_o_d is None else params.a_o_d), n),
        f_p=ego_px - follow_margin - rng.uniform(-1.0, 40.0, n),
        f_v=rng.uniform(0.0, 40.0, n),
        follower_aggressive=rng.random(n) < 0.5,
        leader_human=leader_human,
        follower_human=follower_human,
    )


def take(states: dict, idx) -> dict:
    return {k: np.asarray(v)[idx] for k, v in states.items()}


def margins(states: dict, params: Params):
    lead = np.where(states["leader_human"], params.p_m_human, params.p_m)
    follow = np.where(states["follower_human"], params.p_m_human, params.p_m)
    return lead, follow


def initial_room(states: dict, params: Params):
    """Smaller of the two gaps' excess over their margins at ``t = 0`` [m]."""
    lead, follow = margins(states, params)
    return np.minimum(states["l1_p"] - states["ego_px"] - lead, states["ego_px"] - states["f_p"] - follow)


def near_boundary_infeasible(rng, params, n_states):
    """``n_states`` states the engine calls infeasible by ``SHORTFALL_MIN_M``..``SHORTFALL_MAX_M`` m although
    both gaps are clear at ``t = 0``: three quarters because the follower comes too close, a quarter because even
    full braking cannot keep L1's gap. In the follower cases L1 shapes the plan (it does not accelerate
    throughout), so a better profile would have to trade the two gaps against each other."""
    states = random_states(rng, params, 40_000)
    plan = plan_evasion(**states, params=params)
    lead, follow = margins(states, params)
    lead_short = lead - plan.min_gap_leader
    follow_short = follow - plan.min_gap_follower
    window = lambda s: (s >= SHORTFALL_MIN_M) & (s <= SHORTFALL_MAX_M)  # noqa: E731
    # Both gaps clear at t = 0, so the shortfall comes from the dynamics, not from the initial state.
    base = ~plan.feasible & (plan.t_y_f > 0.3) & (initial_room(states, params) >= 0.2)
    # Follower cases where L1 shapes the plan (not accelerate-throughout): the search must trade the two gaps.
    shaped = plan.t_x1 < plan.t_y_f - 0.05
    too_close = (plan.reason & Reason.FOLLOWER_TOO_CLOSE).astype(bool)
    by_follower = np.flatnonzero(base & too_close & shaped & window(follow_short))
    by_leader = np.flatnonzero(base & (plan.reason & Reason.LEADER_INFEASIBLE).astype(bool) & window(lead_short))
    n_lead = n_states // 4
    idx = np.concatenate([by_follower[: n_states - n_lead], by_leader[:n_lead]])
    assert idx.size == n_states, (by_follower.size, by_leader.size)
    return take(states, idx)


def near_boundary_feasible(rng, params, n_states, room=(0.3, 2.0)):
    """States the engine calls feasible, whose plan keeps the follower gap only ``room`` m above the margin."""
    states = random_states(rng, params, 40_000)
    plan = plan_evasion(**states, params=params)
    lead, follow = margins(states, params)
    spare = plan.min_gap_follower - follow
    ok = plan.feasible & (plan.t_y_f > 0.3) & (spare >= room[0]) & (spare <= room[1])
    ok &= initial_room(states, params) >= 0.2
    ok &= plan.min_gap_leader - lead >= -1e-9
    idx = np.flatnonzero(ok)[:n_states]
    assert idx.size == n_states
    return take(states, idx)


# --------------------------------------------------------------------------------------------------------------
# Random piecewise-constant profiles
# --------------------------------------------------------------------------------------------------------------


def piece_average(T, n_pieces, breaks, values, n_max):
    """Per-piece mean of a phase-wise constant acceleration: phases end at ``breaks`` ``(M, m-1)`` (then ``T``),
    take ``values`` ``(M, m)``. Returns ``(M, n_max)`` (pieces beyond ``n_pieces`` unused)."""
    H = T / n_pieces
    k = np.arange(n_max)[None, :]
    start, end = k * H[:, None], (k + 1) * H[:, None]
    edges = np.concatenate([np.zeros((T.size, 1)), breaks, T[:, None]], axis=1)
    out = np.zeros((T.size, n_max))
    for j in range(values.shape[1]):
        overlap = np.clip(np.minimum(end, edges[:, j + 1 : j + 2]) - np.maximum(start, edges[:, j : j + 1]), 0.0, None)
        out += overlap * values[:, j : j + 1]
    return out / H[:, None]


def random_profiles(rng, params, plan, k):
    """``k`` profiles for each state of ``plan``: piece counts, piece accelerations ``(S·k, 30)``, state index.

    Four families of equal size: uniform random pieces; accelerate–brake with a random switch (half of them near
    the plan's switch); accelerate–brake–hold-a-random-deceleration (half near the plan's switch times); and
    the plan's own profile averaged per piece plus Gaussian noise (σ from 0 to 1 m/s²).
    """
    a_a, a_d = params.a_x_a, params.a_x_d
    n_states = plan.t_y_f.size
    state = np.repeat(np.arange(n_states), k)
    m = state.size
    T = plan.t_y_f[state]
    n_p = rng.choice(PIECE_COUNTS, m)
    n_max = max(PIECE_COUNTS)
    family = np.arange(m) % 4
    near = rng.random(m) < 0.5
    u_plan, t2_plan = plan.t_x1[state], plan.t_x2[state]

    acc = rng.uniform(-a_d, a_a, (m, n_max))  # family 0

    s1 = np.where(near, u_plan + rng.normal(0.0, 0.15, m), rng.uniform(0.0, 1.0, m) * T)
    s1 = np.clip(s1, 0.0, T)
    bang = piece_average(T, n_p, s1[:, None], np.stack([np.full(m, a_a), np.full(m, -a_d)], 1), n_max)

    s2 = np.where(near, t2_plan + rng.normal(0.0, 0.15, m), s1 + rng.uniform(0.0, 1.0, m) * (T - s1))
    s2 = np.clip(s2, s1, T)
    hold = np.where(rng.random(m) < 0.5, -plan.l1_decel[state], -rng.uniform(0.0, a_d, m))
    three = piece_average(T, n_p, np.stack([s1, s2], 1), np.stack([np.full(m, a_a), np.full(m, -a_d), hold], 1), n_max)

    own = np.zeros((m, n_max))
    for n in PIECE_COUNTS:  # the plan's mean acceleration over each of n pieces, for every state
        t_edges = plan.t_y_f[None, :] * np.linspace(0.0, 1.0, n + 1)[:, None]
        _, _, vx, _ = plan.state(t_edges)
        mean_acc = (np.diff(vx, axis=0) / (plan.t_y_f / n)).T  # (S, n)
        sel = n_p == n
        own[sel, :n] = mean_acc[state[sel]]
    sigma = rng.choice([0.0, 0.02, 0.1, 0.3, 1.0], m)
    own = own + sigma[:, None] * rng.standard_normal((m, n_max))

    acc = np.where((family == 1)[:, None], bang, acc)
    acc = np.where((family == 2)[:, None], three, acc)
    acc = np.where((family == 3)[:, None], own, acc)
    return n_p, np.clip(acc, -a_d, a_a), state


def search(params, states, n_per_state, rng):
    """Run the random search; returns ``(plan, best_margin per profile, state index, piece counts)``.

    ``best_margin`` is the smallest over the substep nodes of both gaps minus their margins; a profile is valid
    where it is ``>= 0``. Ego integration is exact per substep (a braking ego that reaches rest stays there).
    """
    plan = plan_evasion(**states, params=params)
    lead_m, follow_m = margins(states, params)
    n_p, acc, state = random_profiles(rng, params, plan, n_per_state)
    T = plan.t_y_f
    h_state = T / N_SUB
    t_nodes = h_state[:, None] * np.arange(N_SUB + 1)[None, :]  # (S, N_SUB+1)
    l1, ff = worst_case_l1_f(states, params, t_nodes.T)
    room_l1 = (l1.T - lead_m[:, None])[state]  # ego must stay at or below this
    room_f = (ff.T + follow_m[:, None])[state]  # ... and at or above this

    p = states["ego_px"][state].copy()
    v = states["ego_vx"][state].copy()
    h = h_state[state]
    rows = np.arange(state.size)
    best = np.minimum(room_l1[:, 0] - p, p - room_f[:, 0])
    for k in range(N_SUB):
        a = acc[rows, (k * n_p) // N_SUB]
        with np.errstate(divide="ignore", invalid="ignore"):
            hh = np.where(a < 0.0, np.minimum(h, v / -a), h)
        p = p + v * hh + 0.5 * a * hh * hh
        v = np.maximum(v + a * hh, 0.0)
        best = np.minimum(best, np.minimum(room_l1[:, k + 1] - p, p - room_f[:, k + 1]))
    return plan, best, state, n_p


def worst_case_l1_f(states: dict, params: Params, t):
    """Reference positions of the worst-case L1 and F at times ``t`` ``(G, S)`` (exact per substep, so a coarse
    substep grid is enough)."""
    spread = lambda x: np.broadcast_to(np.asarray(x), t.shape).ravel()  # noqa: E731
    l1 = braked_position(spread(states["l1_p"]), spread(states["l1_v"]), spread(states["l1_decel"]), t.ravel(), 3)
    ff = follower_position(
        spread(states["f_p"]), spread(states["f_v"]), spread(states["follower_aggressive"]), t.ravel(), params, 3
    )
    return l1.reshape(t.shape), ff.reshape(t.shape)


def node_error_bound(params, plan):
    """Largest amount by which checking gaps at the nodes only can overestimate their minimum [m]."""
    h = plan.t_y_f / N_SUB
    return (params.a_x_a + params.a_x_d) * h * h / 8.0


# --------------------------------------------------------------------------------------------------------------
# Tests
# --------------------------------------------------------------------------------------------------------------


def test_random_search_finds_no_evasion_where_engine_finds_none():
    total = 0
    for i, (name, params) in enumerate(PARAMS_SETS.items()):
        rng = np.random.default_rng(2024 + i)
        states = near_boundary_infeasible(rng, params, N_STATES)
        plan, best, state, _ = search(params, states, PROFILES_PER_STATE, rng)
        assert not plan.feasible.any()
        assert SHORTFALL_MIN_M > 4.0 * node_error_bound(params, plan).max()
        valid = best >= 0.0
        if valid.any():
            j = int(np.argmax(best))
            raise AssertionError(
                f"[{name}] profile {j} keeps both gaps (margin {best[j]:.3g} m) for a state the engine calls "
                f"infeasible: {take(states, state[j])}"
            )
        total += best.size
    assert total >= MIN_PROFILES


def test_random_search_has_power_on_feasible_states():
    """With 0.3–2 m to spare, the search finds a valid profile for nearly every state the engine calls feasible."""
    for i, (name, params) in enumerate(PARAMS_SETS.items()):
        rng = np.random.default_rng(7 + i)
        states = near_boundary_feasible(rng, params, 16)
        _, best, state, _ = search(params, states, 512, rng)
        found = np.zeros(16, dtype=bool)
        np.logical_or.at(found, state, best >= 0.0)
        assert found.mean() >= 0.9, (name, found)


def test_engine_plans_keep_both_gaps():
    n_grid = 400
    for i, (name, params) in enumerate(PARAMS_SETS.items()):
        rng = np.random.default_rng(99 + i)
        states = random_states(rng, params, 6_000)
        plan = plan_evasion(**states, params=params)
        ok = plan.feasible & (plan.t_y_f > 0.0)
        assert ok.sum() > 2_000, (name, ok.sum())
        states, plan = take(states, ok), plan_evasion(**take(states, ok), params=params)
        lead_m, follow_m = margins(states, params)
        T = plan.t_y_f
        t = T[None, :] * np.linspace(0.0, 1.0, n_grid + 1)[:, None]  # (G, S)
        px, _, vx, vy = plan.state(t)
        l1, ff = worst_case_l1_f(states, params, t)
        lead_gap = l1 - px - lead_m
        follow_gap = px - ff - follow_m
        assert lead_gap.min() >= -GAP_TOL_M, (name, lead_gap.min())
        assert follow_gap.min() >= -GAP_TOL_M, (name, follow_gap.min())

        # Within the limits: speeds >= 0, mean accelerations between nodes within [-a_x_d, a_x_a], positions
        # consistent with speeds, lateral accelerations within ±a_y_m.
        dt = np.diff(t, axis=0)
        assert vx.min() >= -1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            ax = np.where(dt > 0, np.diff(vx, axis=0) / dt, 0.0)
            ay = np.where(dt > 0, np.diff(vy, axis=0) / dt, 0.0)
        assert ax.min() >= -params.a_x_d - 1e-6 and ax.max() <= params.a_x_a + 1e-6, name
        assert np.abs(ay).max() <= params.a_y_m + 1e-6, name
        trapezoid = 0.5 * (vx[1:] + vx[:-1]) * dt
        assert np.all(np.abs(np.diff(px, axis=0) - trapezoid) <= (params.a_x_a + params.a_x_d) * dt**2 / 8 + 1e-9)

        # Back in the own lane from t_y_f on, at rest laterally if it can stop there.
        after = T[None, :] * np.array([1.0, 1.001, 1.5, 3.0])[:, None] + np.array([0.0, 0.0, 0.1, 1.0])[:, None]
        _, py_after, _, vy_after = plan.state(after)
        assert py_after.max() <= params.y_safe + 1e-9, name
        assert np.all(vy_after <= 1e-9), name
