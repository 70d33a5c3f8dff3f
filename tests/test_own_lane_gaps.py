"""The gap minima of the own-lane evasion (``safelane.safety.own_lane``: :func:`leader_gap`, :func:`follower_gap`)
and every part :func:`own_lane_core` returns, against the independent time-stepped reference
(``tests/reference_own_lane.py``: simulated kinematics, the meeting instant by bisection, no engine closed forms).

The engine's family member ``G(u, k)`` is the reference's ``Profile(u, 0, a_x_d, k)``: for random switch times
``u`` (including 0, ``t_y_f`` and beyond), both followed leaders, stopped and never-stopping vehicles, the engine's
minimum gap to ``L0`` over ``[0, ∞)`` (``-inf`` where the ego ends faster), to ``L1`` and from the worst-case ``F``
over ``[0, T]`` must equal the reference's, margin subtracted. Seeded, a few hundred rows per case: fast.
"""

from __future__ import annotations

import numpy as np
import pytest

from reference_own_lane import Profile, Scene, _events, profile_gaps
from safelane import Params
from safelane.safety.own_lane import INF, follower_gap, leader_gap, own_lane_core
from test_own_lane import random_params, random_states, scene_of

#: Agreement of two exact computations (closed form vs time stepping), in metres / seconds.
ATOL = 1e-6
N = 400


def _rows(seed: int, kind: str):
    """``(prm, kw, T, u)``: random own-lane states (``test_own_lane.random_states``), a horizon ``T`` per row (a
    tenth 0), and switch times ``u`` in ``[0, 1.2 T]`` (a tenth exactly 0, a tenth exactly ``T``)."""
    rng = np.random.default_rng(seed)
    prm = Params() if kind == "default" else random_params(rng)
    kw = random_states(rng, prm, N)
    # Extra corners: L1 never stopping (decel 0) or stopped, F stopped, the ego stopped, L0 stopped.
    kw["l1_decel"][::9] = 0.0
    kw["l1_v"][::11] = 0.0
    kw["f_v"][::13] = 0.0
    kw["ego_vx"][::17] = 0.0
    kw["l0_v"][::19] = 0.0
    # Decelerations one apart (a unit denominator of the equal-speed instants): L0 at a_x_d − 1 (the braking ego
    # closes on it until their speeds meet), L1 at L0's + 1.
    kw["l0_decel"][3::7] = prm.a_x_d - 1.0
    kw["l1_decel"][5::7] = np.minimum(kw["l0_decel"][5::7] + 1.0, prm.a_x_d)
    T = np.where(rng.random(N) < 0.1, 0.0, rng.uniform(0.2, 6.0, N))
    u = rng.uniform(0.0, 1.2, N) * T
    u[::10] = 0.0
    u[5::10] = T[5::10]
    return prm, kw, T, u


def _leaders(kw):
    l1 = (kw["l1_p"], kw["l1_v"], kw["l1_decel"])
    l0 = (kw["l0_p"], kw["l0_v"], kw["l0_decel"])
    return l1, l0


def _assert_gap(engine, ref, what):
    engine, ref = np.asarray(engine, float), np.asarray(ref, float)
    same_inf = np.isinf(engine) & np.isinf(ref) & (np.sign(engine) == np.sign(ref))
    close = np.isclose(engine, ref, rtol=1e-9, atol=ATOL)
    bad = np.flatnonzero(~(same_inf | close))
    assert bad.size == 0, f"{what}: rows {bad[:5]}: engine {engine[bad[:5]]}, reference {ref[bad[:5]]}"


@pytest.mark.parametrize("kind", ["default", "random"])
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("k", [0, 1])
def test_gap_minima_equal_the_time_stepped_reference(seed, kind, k):
    """Each gap of ``G(u, k)`` (the followed leader ``k``: 0 = L0, 1 = L1) equals the reference's exact minimum,
    margin subtracted: to L0 over ``[0, ∞)`` (and over ``[0, T]`` when following it), to L1 and from F over
    ``[0, T]`` (per-row and scalar ``T``)."""
    prm, kw, T, u = _rows(100 * seed + k, kind)
    l1, l0 = _leaders(kw)
    lead = l0 if k == 0 else l1
    p, v = kw["ego_px"], kw["ego_vx"]
    scene = Scene(p, v, *l1, *l0, kw["f_p"], kw["f_v"], np.asarray(kw["aggressive"], bool), T)
    ref = profile_gaps(scene, Profile(u, np.zeros(N), np.full(N, prm.a_x_d), np.full(N, k)), prm)
    om, lm, fm = kw["own_margin"], kw["lead_margin"], kw["follow_margin"]
    _assert_gap(leader_gap(u, p, v, lead, l0, om, INF, prm), ref.own - om, "L0 over [0, inf)")
    _assert_gap(leader_gap(u, p, v, lead, l1, lm, T, prm), ref.l1 - lm, "L1 over [0, T]")
    _assert_gap(follower_gap(u, p, v, lead, kw["f_p"], kw["f_v"], kw["aggressive"], fm, T, prm), ref.f - fm,
                "F over [0, T]")  # fmt: skip
    # L0 over the finite horizon [0, T]: the reference's L1 gap with L0 put in L1's place (following L0 = k 1).
    scene0 = Scene(p, v, *l0, *l0, kw["f_p"], kw["f_v"], np.asarray(kw["aggressive"], bool), T)
    ref0 = profile_gaps(scene0, Profile(u, np.zeros(N), np.full(N, prm.a_x_d), np.full(N, 1 if k == 0 else -1)), prm)
    if k == 0:
        _assert_gap(leader_gap(u, p, v, l0, l0, om, T, prm), ref0.l1 - om, "L0 over [0, T]")
    # Scalar horizons broadcast like per-row ones.
    T_one = 2.5
    one = Scene(p, v, *l1, *l0, kw["f_p"], kw["f_v"], np.asarray(kw["aggressive"], bool), np.full(N, T_one))
    ref1 = profile_gaps(one, Profile(np.minimum(u, T_one), np.zeros(N), np.full(N, prm.a_x_d), np.full(N, k)), prm)
    _assert_gap(leader_gap(np.minimum(u, T_one), p, v, lead, l1, lm, T_one, prm), ref1.l1 - lm, "L1, scalar T")


def test_the_gap_to_l0_is_minus_infinity_exactly_when_the_ego_ends_faster():
    """Following L1 that never stops (decel 0) at 20 m/s behind a stopping L0: the ego ends faster, the gap to L0
    shrinks forever (``-inf``). Following L1 at 20 m/s behind L0 cruising at 20.5 m/s (decel 0 is outside L0's
    range, so L0 brakes at 1e-12: it ends slower by round-off only after ~2e13 s — the reference says the same):
    finite. And an ego ending slower than L0 by 0.5 m/s: finite (a speed excess of 0.5 m/s is not round-off)."""
    prm = Params()
    one = lambda x: np.atleast_1d(np.asarray(x, float))  # noqa: E731
    p, v = one(0.0), one(20.0)
    l1 = (one(100.0), one(20.0), one(0.0))
    # L0 stops (20 m/s at 8 m/s²): the ego, following L1 forever at 20 m/s, runs into it.
    g = leader_gap(one(0.0), p, v, l1, (one(50.0), one(20.0), one(8.0)), one(7.0), INF, prm)
    assert g[0] == -np.inf
    # L1 at 19.5 m/s never stopping, L0 at 20 m/s braking at 8: the ego still ends faster (L0 stops).
    l1_slow = (one(100.0), one(19.5), one(0.0))
    g = leader_gap(one(0.0), p, v, l1_slow, (one(50.0), one(20.0), one(8.0)), one(7.0), INF, prm)
    assert g[0] == -np.inf
    # A crawling L1 (0.5 m/s, never stopping) behind a stopped L0: the ego ends 0.5 m/s faster, not round-off.
    l1_crawl = (one(100.0), one(0.5), one(0.0))
    g = leader_gap(one(0.0), p, v, l1_crawl, (one(80.0), one(0.0), one(8.0)), one(7.0), INF, prm)
    assert g[0] == -np.inf
    # The ego ending exactly SPEED_TOL (1e-9 m/s) faster is round-off by the module's convention: finite; 2e-9: not.
    for crawl, closing in ((1e-9, False), (2e-9, True)):
        g = leader_gap(one(0.0), p, v, (one(100.0), one(crawl), one(0.0)), (one(80.0), one(0.0), one(8.0)), one(7.0),
                       INF, prm)  # fmt: skip
        assert (g[0] == -np.inf) == closing
    # Following L0 itself: the ego ends at L0's speed, never faster: the minimum is finite.
    l0 = (one(30.0), one(15.0), one(3.0))
    g = leader_gap(one(0.0), p, v, l0, l0, one(7.0), INF, prm)
    assert np.isfinite(g[0])
    # The ego brakes to rest (no leader to follow is moving) behind a stopped L0: the gap ends constant, finite.
    l0_stopped = (one(60.0), one(0.0), one(8.0))
    g = leader_gap(one(0.0), p, v, l0_stopped, l0_stopped, one(7.0), INF, prm)
    assert g[0] == pytest.approx(60.0 - 20.0**2 / (2 * 8.0) - 7.0, abs=1e-9)


@pytest.mark.parametrize("kind", ["default", "random"])
@pytest.mark.parametrize("seed", range(3))
def test_every_part_of_the_core_matches_the_reference(seed, kind):
    """``own_lane_core``'s parts describe the profile it chose, as the reference simulates it: ``v_switch`` is the
    speed after accelerating for ``t_x1``, ``t_brake_end`` the end of braking (the meeting by bisection, or the
    stop), ``follows_leader`` whether it follows, and ``lead_gap``, ``follow_gap``, ``own_gap`` the reference's
    gap minima of that profile minus the margins (L1 and F only where there is something to evade)."""
    rng = np.random.default_rng(1000 + seed)
    prm = Params() if kind == "default" else random_params(rng)
    kw = random_states(rng, prm, N)
    kw["ego_vx"][::17] = 0.0
    kw["l1_v"][::11] = 0.0
    with np.errstate(all="raise"):  # no floating-point warning on valid states (every division is guarded)
        exists, parts = own_lane_core(**kw, prm=prm)
    T = np.broadcast_to(np.asarray(parts["t_y_f"], float), (N,)).copy()
    u = parts["t_x1"]
    k = np.where(parts["follows_own"], 0, 1)
    scene = scene_of(kw, T)
    prof = Profile(u, np.zeros(N), np.full(N, prm.a_x_d), k)
    gaps = profile_gaps(scene, prof, prm)
    _, brake_end, match, _, _ = _events(scene, prof, prm)
    np.testing.assert_allclose(parts["v_switch"], kw["ego_vx"] + prm.a_x_a * u, rtol=1e-12, atol=1e-12)
    # The meeting instant: where the reference and the engine disagree on "follows", the speeds meet at the end.
    agree = parts["follows_leader"] == match
    assert agree.mean() > 0.99
    np.testing.assert_allclose(parts["t_brake_end"][agree], brake_end[agree], rtol=1e-9, atol=1e-6)
    evading = T > 0.0
    assert np.array_equal(parts["nothing"], ~evading)
    _assert_gap(parts["own_gap"], gaps.own - kw["own_margin"], "own_gap")
    _assert_gap(parts["lead_gap"][evading], (gaps.l1 - kw["lead_margin"])[evading], "lead_gap")
    _assert_gap(parts["follow_gap"][evading], (gaps.f - kw["follow_margin"])[evading], "follow_gap")
    assert np.all(parts["lead_gap"][~evading] == np.inf) and np.all(parts["follow_gap"][~evading] == np.inf)
    # The verdicts are the gaps' (tolerance 1e-9 m).
    tol = 1e-9
    assert np.array_equal(parts["lead_ok"], np.minimum(parts["own_gap"], parts["lead_gap"]) >= -tol)
    assert np.array_equal(parts["follow_ok"], parts["follow_gap"] >= -tol)
    assert np.array_equal(exists, parts["lead_ok"] & parts["follow_ok"])
    # Follows L0 only where following L1 fails and following L0 succeeds: never when exists is false.
    assert not (parts["follows_own"] & ~exists).any()
    assert parts["follows_own"].any() and (exists & ~parts["follows_own"]).any() and (~exists).any()
    for name in ("t_y_switch", "y_acc_1", "y_acc_2", "t_y_end"):
        assert np.shape(parts[name]) in ((), (N,))
    # Plain float64 arrays (no object dtype sneaking in through a closed form's fallback value).
    for name in ("t_x1", "v_switch", "t_brake_end", "lead_gap", "follow_gap", "own_gap"):
        assert parts[name].dtype == np.float64, name


@pytest.mark.parametrize("target", [0.0, -0.3e-9, -1.2e-9, -1e-6])
def test_the_search_keeps_the_best_feasible_switch_time_at_its_tolerance(target):
    """The hand case of ``test_own_lane.test_l0_caps_the_acceleration_phase_of_an_intruding_ego`` (L1 and F far,
    L0 at 20 m/s braking at 8, the ego intruding 1 m at 20 m/s: ``t_y_f = 2·sqrt(1/1.5)``), with L0 placed so that
    the gap to it at ``u = t_y_f/2`` (the bisection's first midpoint) is ``target``: the gap after accelerating for
    ``u`` is ``slack − 26.25 u − 1.640625 u²``. The search's contract: the switch time it returns keeps the gap
    ``>= −tol/2`` (``tol`` = 1e-9 m) — so the evasion exists — and is short of the largest such ``u`` (the root of
    ``26.25 u + 1.640625 u² = slack + tol/2``, by the quadratic formula) by at most ``t_y_f·2⁻¹⁶``, on the grid of
    the module's documented 16 halvings of ``[0, t_y_f]``."""
    T = 2.0 * np.sqrt(1.0 / 1.5)
    m = 0.5 * T
    slack = 26.25 * m + 1.640625 * m * m + target
    kw = {k: np.atleast_1d(np.asarray(v, bool if k == "aggressive" else float)) for k, v in dict(
        ego_px=0.0, ego_py=0.85 + 1.0, ego_vx=20.0, ego_vy=0.0, l1_p=200.0, l1_v=30.0, l1_decel=0.0, f_p=-100.0,
        f_v=0.0, aggressive=False, l0_p=7.0 + slack, l0_v=20.0, l0_decel=8.0, lead_margin=7.0, follow_margin=7.0,
        own_margin=7.0).items()}  # fmt: skip
    exists, parts = own_lane_core(**kw, prm=Params())
    assert parts["t_y_f"][0] == pytest.approx(T, rel=1e-12)
    assert exists[0]
    assert parts["own_gap"][0] >= -0.5e-9
    a, b, c = 1.640625, 26.25, -(slack + 0.5e-9)
    u_best = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    assert parts["t_x1"][0] <= u_best + 1e-12
    assert parts["t_x1"][0] >= u_best - T * 2.0**-16
    # Where the search ran (u below the closed form's T), u is on its documented grid: 16 halvings of [0, T].
    if parts["t_x1"][0] < T:
        k = parts["t_x1"][0] / T * 2.0**16
        assert abs(k - round(k)) < 1e-6, k


@pytest.mark.parametrize("offset, exists", [(-0.4e-9, True), (-0.75e-9, True), (-1.2e-9, False), (1e-3, True)])
def test_braking_at_once_within_the_tolerance_is_an_evasion(offset, exists):
    """Regression (found by mutation testing): L0 at the ego's 20 m/s, braking at 2, ``offset`` beyond its margin;
    L1 at 10 m/s braking at 8, 28 m ahead; F far behind at rest; the ego intruding 1 m. Braking at ``a_x_d`` from
    t = 0 (``G(0, L1)``) keeps the gap to L0 at its initial ``offset`` (the ego brakes harder), the gap to L1 ≥ 12 m
    (the reference's simulation, below) and F's: so an evasion exists iff ``offset >= −tol`` (``tol`` = 1e-9 m,
    gaps within it count as kept). Before the fix, an L0 gap at 0 in ``[−tol, −tol/2)`` skipped the search and kept
    the closed form's (infeasible) switch time: no evasion at −0.75 nm, one at −0.4 nm."""
    prm = Params()
    kw = {k: np.atleast_1d(np.asarray(v, bool if k == "aggressive" else float)) for k, v in dict(
        ego_px=0.0, ego_py=0.85 + 1.0, ego_vx=20.0, ego_vy=0.0, l1_p=28.0, l1_v=10.0, l1_decel=8.0, f_p=-100.0,
        f_v=0.0, aggressive=False, l0_p=7.0 + offset, l0_v=20.0, l0_decel=2.0, lead_margin=7.0, follow_margin=7.0,
        own_margin=7.0).items()}  # fmt: skip
    got, parts = own_lane_core(**kw, prm=prm)
    T = np.atleast_1d(parts["t_y_f"])
    scene = Scene(kw["ego_px"], kw["ego_vx"], kw["l1_p"], kw["l1_v"], kw["l1_decel"], kw["l0_p"], kw["l0_v"],
                  kw["l0_decel"], kw["f_p"], kw["f_v"], kw["aggressive"], T)  # fmt: skip
    at_once = profile_gaps(scene, Profile(np.zeros(1), np.zeros(1), np.full(1, prm.a_x_d), np.array([1])), prm)
    assert at_once.own[0] - 7.0 == pytest.approx(offset, abs=1e-12)
    assert at_once.l1[0] - 7.0 > 5.0 and at_once.f[0] - 7.0 > 50.0
    assert bool(got[0]) == exists
    if exists:
        assert parts["own_gap"][0] >= -1e-9 and parts["lead_gap"][0] >= -1e-9


@pytest.mark.parametrize("seed, l0_gap", [(0, 2000.0), (1, 2000.0), (2, 0.5e-9), (3, 0.0)])
def test_a_far_l0_leaves_the_papers_evasion_as_it_is(seed, l0_gap):
    """L0 ``l0_gap`` beyond its margin (2 km; or right at it, within the 1 nm tolerance) at 50 m/s, not braking: it
    only pulls away, so it never binds. Wherever the paper's evasion (no L0, :func:`safelane.safety.plan_evasion`)
    exists, the own-lane check finds the same one — following L1, with the paper's switch time exactly (the closed
    form is not shortened by a search it does not need) and its L1 gap; where L1 is already inside its margin, no
    switch time (0), as in the paper."""
    from safelane.safety import plan_evasion

    rng = np.random.default_rng(300 + seed)
    prm = Params()
    kw = random_states(rng, prm, N)
    kw["lead_margin"] = kw["follow_margin"] = np.full(N, prm.p_m)
    kw["l0_p"] = kw["ego_px"] + prm.p_m + l0_gap
    kw["l0_v"], kw["l0_decel"] = np.full(N, 50.0), np.zeros(N)
    exists, parts = own_lane_core(**kw, prm=prm)
    paper = plan_evasion(kw["ego_px"], kw["ego_py"], kw["ego_vx"], kw["ego_vy"], kw["l1_p"], kw["l1_v"],
                         kw["l1_decel"], kw["f_p"], kw["f_v"], kw["aggressive"], prm)  # fmt: skip
    both = paper.feasible
    evading = paper.t_y_f > 0.0
    assert (both & evading).sum() > 50
    assert exists[both].all()
    assert not parts["follows_own"][both].any()
    np.testing.assert_array_equal(parts["t_x1"][both & evading], paper.t_x1[both & evading])
    np.testing.assert_allclose(parts["lead_gap"][both & evading], (paper.min_gap_leader - prm.p_m)[both & evading],
                               rtol=1e-9, atol=1e-9)  # fmt: skip
    assert (parts["t_x1"][both & evading] > 0.0).sum() > 20
    inside = kw["l1_p"] - kw["ego_px"] - prm.p_m < -1e-6
    assert (inside & evading).sum() > 5
    assert not exists[inside & evading].any()
    np.testing.assert_array_equal(parts["t_x1"][inside & evading], 0.0)


def test_the_tolerance_is_the_callers():
    """``tol`` is passed through to the closed form: ego and L1 at 20 m/s (L1 not braking), L0 far and faster, F far
    behind, the ego intruding 1 m (``t_y_f = 2·sqrt(1/1.5)`` = T). Accelerating throughout ``[0, T]`` closes on L1 by
    ``a_x_a T²/2`` = 1.25 T² by T (the braking comes after T, outside L1's window); L1 is placed so that this
    leaves the gap 0.5 mm inside the margin. With ``tol = 1e-3`` that is kept: ``u = T``; with the default 1 nm
    the switch comes earlier and the gap stays within 1 nm."""
    T = 2.0 * np.sqrt(1.0 / 1.5)
    kw = {k: np.atleast_1d(np.asarray(v, bool if k == "aggressive" else float)) for k, v in dict(
        ego_px=0.0, ego_py=0.85 + 1.0, ego_vx=20.0, ego_vy=0.0, l1_p=7.0 + 1.25 * T * T - 0.5e-3, l1_v=20.0,
        l1_decel=0.0, f_p=-100.0, f_v=0.0, aggressive=False, l0_p=2000.0, l0_v=50.0, l0_decel=0.0, lead_margin=7.0,
        follow_margin=7.0, own_margin=7.0).items()}  # fmt: skip
    exists, parts = own_lane_core(**kw, prm=Params(), tol=1e-3)
    assert exists[0] and not parts["follows_own"][0]
    assert parts["t_x1"][0] == pytest.approx(T, rel=1e-12)
    assert parts["lead_gap"][0] == pytest.approx(-0.5e-3, abs=1e-9)
    exists, parts = own_lane_core(**kw, prm=Params())
    assert exists[0] and parts["t_x1"][0] < T - 1e-6 and parts["lead_gap"][0] >= -1e-9


def test_a_follower_exactly_at_its_margin_keeps_it():
    """F at rest exactly ``p_m`` behind the ego (which never reverses): the follower gap's minimum is 0, at t = 0,
    kept; 1 mm closer it is not. L1 and L0 far and fast, the ego intruding 1 m at 20 m/s."""
    for offset, ok in ((0.0, True), (-1e-3, False)):
        kw = {k: np.atleast_1d(np.asarray(v, bool if k == "aggressive" else float)) for k, v in dict(
            ego_px=10.0, ego_py=0.85 + 1.0, ego_vx=20.0, ego_vy=0.0, l1_p=500.0, l1_v=50.0, l1_decel=0.0,
            f_p=10.0 - 7.0 - offset, f_v=0.0, aggressive=False, l0_p=1000.0, l0_v=50.0, l0_decel=0.0,
            lead_margin=7.0, follow_margin=7.0, own_margin=7.0).items()}  # fmt: skip
        exists, parts = own_lane_core(**kw, prm=Params())
        assert parts["follow_gap"][0] == pytest.approx(offset, abs=1e-12)
        assert bool(exists[0]) == ok and bool(parts["follow_ok"][0]) == ok


def _own_period_reference(ego_x, ego_vx, a_x, l0_x, l0_v, l0_decel, dt, n=4001):
    """Time-stepped reference of :func:`own_period`'s motion: both vehicles at constant acceleration over ``[0, dt]``
    (``n`` instants, both ends included), each stopping at rest rather than reversing. Returns ``(min over the
    instants of l0 − ego, L0's position and speed at dt)``."""
    t = np.linspace(0.0, 1.0, n)[None, :] * dt[:, None]

    def pos(x, v, a):
        # The instant it reaches rest (never where it accelerates, or is at rest and not pushed forward).
        stop = np.where(a < 0.0, v / np.where(a < 0.0, -a, 1.0), np.where((v <= 0.0) & (a <= 0.0), 0.0, np.inf))
        tt = np.minimum(t, stop[:, None])
        return x[:, None] + v[:, None] * tt + 0.5 * a[:, None] * tt * tt, np.maximum(v + a * dt, 0.0)

    ego, _ = pos(ego_x, ego_vx, a_x)
    l0, l0_v_end = pos(l0_x, l0_v, -l0_decel)
    return (l0 - ego).min(axis=1), l0[:, -1], l0_v_end


def test_own_period_keeps_l0_over_the_period_as_the_time_stepped_reference():
    """``own_period`` (the shield's check of ``L0`` over one period, ``shield/decide.py``) against a time-stepped
    reference: random egos (accelerating, cruising, braking to rest within the period) behind an ``L0`` braking at
    up to ``a_x_d``, at positions away from 0; the period stays safe iff the minimum gap over the period stays
    ``>= p_m − tol/2`` (rows within 1 mm of the boundary are left out: the reference samples), ``L0``'s state at the
    period's end is its exact braked state, the step completes only where it did and ``ego_vy_end >= 0``, and a
    period already failed stays failed."""
    from safelane.safety._backend import ARRAY
    from safelane.safety.own_lane import own_period

    rng = np.random.default_rng(77)
    prm, n = Params(), 600
    ego_x = rng.uniform(-300.0, 300.0, n)
    ego_vx = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.0, 35.0, n))
    a_x = rng.uniform(-prm.a_x_d, prm.a_x_a, n)
    l0_v = np.maximum(ego_vx + rng.normal(0.0, 6.0, n), 0.0)
    l0_decel = np.where(rng.random(n) < 0.3, prm.a_x_d, rng.uniform(0.0, prm.a_x_d, n))
    l0_x = ego_x + prm.p_m + rng.uniform(-1.0, 6.0, n)
    dt = rng.uniform(0.05, 1.0, n)
    period_in, completing_in = rng.random(n) < 0.9, rng.random(n) < 0.8
    vy_end = rng.uniform(-1.0, 1.0, n)
    tol = 1e-9
    ok, completing, x_end, v_end = own_period(ARRAY, ego_x, ego_vx, a_x, l0_x, l0_v, l0_decel, period_in,
                                              completing_in, vy_end, prm.p_m, dt, tol)  # fmt: skip
    gap, ref_x, ref_v = _own_period_reference(ego_x, ego_vx, a_x, l0_x, l0_v, l0_decel, dt)
    gap = gap - prm.p_m
    clear = np.abs(gap) > 1e-3
    assert (clear & (gap < 0.0) & period_in).sum() > 50 and (clear & (gap > 0.0) & period_in).sum() > 50
    np.testing.assert_array_equal(ok[clear], (period_in & (gap >= 0.0))[clear])
    np.testing.assert_allclose(x_end, ref_x, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(v_end, ref_v, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(completing, completing_in & (vy_end >= 0.0))


@pytest.mark.parametrize("tol, offset, kept", [(2.0, -1.0, True), (2.0, -1.0 - 2.0**-20, False), (0.0, 0.0, True)])
def test_own_period_keeps_a_gap_exactly_at_half_its_tolerance(tol, offset, kept):
    """Ego and ``L0`` at rest, ``L0`` exactly ``p_m + offset`` ahead (dyadic numbers: every gap is exact): the period
    is kept iff the gap ``offset >= −tol/2`` — at ``−tol/2`` itself it is (``tol`` is the caller's)."""
    from safelane.safety._backend import ARRAY
    from safelane.safety.own_lane import own_period

    one = lambda x: np.atleast_1d(np.asarray(x, float))  # noqa: E731
    yes = np.array([True])
    ok, completing, x_end, v_end = own_period(ARRAY, one(8.0), one(0.0), one(0.0), one(8.0 + 7.0 + offset), one(0.0),
                                              one(6.0), yes, yes, one(0.0), 7.0, 0.5, tol)  # fmt: skip
    assert bool(ok[0]) == kept and bool(completing[0])
    assert x_end[0] == 15.0 + offset and v_end[0] == 0.0


@pytest.mark.parametrize("offset, exists", [(-0.5, True), (-0.5 - 2.0**-20, False)])
def test_a_gap_exactly_at_the_callers_tolerance_is_kept(offset, exists):
    """The case of :func:`test_braking_at_once_within_the_tolerance_is_an_evasion` (braking at once keeps the gap to
    L0 at its initial ``offset``; L1 and F clear) with ``tol = 0.5`` and dyadic positions, so every gap is exact:
    at ``offset = −tol`` exactly the evasion exists (a gap of ``−tol`` counts as kept) with ``own_gap == −0.5`` and
    the switch time 0; a hair beyond, none. And F exactly ``tol`` inside its margin: kept, a hair more: not."""
    prm = Params()
    kw = {k: np.atleast_1d(np.asarray(v, bool if k == "aggressive" else float)) for k, v in dict(
        ego_px=0.0, ego_py=0.85 + 1.0, ego_vx=20.0, ego_vy=0.0, l1_p=28.0, l1_v=10.0, l1_decel=8.0, f_p=-100.0,
        f_v=0.0, aggressive=False, l0_p=7.0 + offset, l0_v=20.0, l0_decel=2.0, lead_margin=7.0, follow_margin=7.0,
        own_margin=7.0).items()}  # fmt: skip
    got, parts = own_lane_core(**kw, prm=prm, tol=0.5)
    assert bool(got[0]) == exists and bool(parts["lead_ok"][0]) == exists
    assert parts["own_gap"][0] == offset and parts["t_x1"][0] == 0.0
    # F at rest exactly `-offset` inside its margin behind the ego (L1 and L0 far and fast).
    kw.update(l1_p=np.array([500.0]), l1_v=np.array([50.0]), l1_decel=np.array([0.0]), l0_p=np.array([1000.0]),
              l0_v=np.array([50.0]), l0_decel=np.array([0.0]), f_p=np.array([-7.0 - offset]))  # fmt: skip
    got, parts = own_lane_core(**kw, prm=prm, tol=0.5)
    assert parts["follow_gap"][0] == offset
    assert bool(got[0]) == exists and bool(parts["follow_ok"][0]) == exists
