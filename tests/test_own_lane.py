"""The evasion check with an own-lane leader ``L0`` (``safelane.safety.own_lane``, issue 17) against an independent
numeric reference (``tests/reference_own_lane.py``: time-stepped kinematics, bisection, brute force over
piecewise-constant profiles; no engine closed forms).

* **soundness**: wherever :func:`own_lane_core` says an evasion exists, the profile it returns (``t_x1``, the
  followed leader), simulated by the reference, keeps ``p_m`` to ``L0`` over ``[0, ∞)`` and to ``L1`` and the
  worst-case ``F`` over ``[0, t_y_f]`` (to ``SOUND_TOL_M``);
* **completeness within the family** ``G(u, k)``: where it says none exists, no profile of a 400-point grid of
  ``u ∈ [0, t_y_f]`` × ``k ∈ {L1, L0}`` keeps every margin with ``COMPLETE_SLACK_M`` to spare (the grid profile
  with ``u − t_y_f·2⁻¹⁵`` as well: the engine's bisection may stop that far short of the family's optimum);
* **optimality gap**: how often a broader piecewise-constant family (softer braking, holding the speed, braking to
  rest without following) finds an evasion that ``G`` misses — printed, asserted small;
* hand-computed cases, and the shield bit for bit unchanged where ``L0`` is absent (``+inf``).

Each Hypothesis example draws a seed and a parameter kind and builds ``BATCH`` random states (derandomized, see
``conftest.py``); ``-m slow`` runs the larger campaigns.
"""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reference import ref_lateral_time
from reference_own_lane import (
    Profile,
    Scene,
    broad_variants,
    family_search,
    g_variants,
    margins_kept,
    profile_gaps,
)
from safelane import Params
from safelane.safety.own_lane import SEARCH_STEPS, own_lane_core
from safelane.shield import SensingBounds, Shield, ShieldConfig, Situation

#: A plan the engine accepts may come this close to a margin (its tolerance is 1e-9 m; the rest is round-off of
#: two different time steppings).
SOUND_TOL_M = 1e-6
#: A grid profile that keeps every margin with this much to spare is an evasion the engine must find.
COMPLETE_SLACK_M = 1e-6
#: Grid points in u for the completeness search (the broad family's search uses BROAD_N_U).
GRID_N_U = 400
BROAD_N_U = 100
#: The optimality gap asserted (share of all drawn states where the broader family finds an evasion G misses).
MAX_GAP_SHARE = 0.05
BATCH = 64

SETTINGS = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
SEEDS = st.integers(min_value=0, max_value=2**63 - 1)
KINDS = st.sampled_from(["default", "default", "random"])


def slow_unless_selected(request, big: bool):
    if big and "slow" not in (request.config.getoption("markexpr") or ""):
        pytest.skip("long campaign: run with -m slow")


# --------------------------------------------------------------------------------------------------------------
# Random states
# --------------------------------------------------------------------------------------------------------------


def random_params(rng) -> Params:
    length = rng.uniform(3.5, 5.5)
    p_m = rng.uniform(length, 12.0)
    return Params(a_x_a=rng.uniform(1.0, 4.0), a_x_d=rng.uniform(4.0, 10.0), a_y_m=rng.uniform(0.5, 3.0),
                  lane_width=rng.uniform(3.0, 4.2), vehicle_width=rng.uniform(1.5, 2.2), vehicle_length=length,
                  p_m=p_m, p_m_human=p_m + rng.uniform(0.0, 5.0))  # fmt: skip


def _slack(rng, n, hi, neg=2.0):
    """Gap beyond a margin: half log-uniform in ``[1e-2, hi]`` (tight), half uniform in ``[-neg, hi/3]``."""
    return np.where(rng.random(n) < 0.5, np.exp(rng.uniform(np.log(1e-2), np.log(hi), n)), rng.uniform(-neg, hi / 3, n))


def random_states(rng, prm: Params, n: int) -> dict:
    """Keyword arguments of :func:`own_lane_core`: ego lateral states of every kind (a fifth with nothing to evade),
    L1, F (aggressive or not), and L0 close ahead at about the ego's speed, braking at ``(0, a_x_d]`` (a third
    exactly at ``a_x_d``); margins ``p_m`` or ``p_m_human``."""
    y_s = prm.y_safe
    kind = rng.integers(0, 5, n)
    py = np.where(kind == 0, y_s - rng.uniform(0.0, 1.0, n), y_s + rng.uniform(0.0, prm.lane_width - y_s, n))
    vy = np.where(kind == 0, -rng.uniform(0.0, 1.0, n), rng.uniform(-2.0, 2.0, n))
    ex = rng.uniform(-200.0, 200.0, n)
    ev = np.where(rng.random(n) < 0.05, 0.0, rng.uniform(0.0, 35.0, n))
    lead_m = np.where(rng.random(n) < 0.2, prm.p_m_human, prm.p_m)
    follow_m = np.where(rng.random(n) < 0.2, prm.p_m_human, prm.p_m)
    l0_v = np.maximum(ev + rng.normal(0.0, 5.0, n), 0.0)
    return dict(
        ego_px=ex, ego_py=py, ego_vx=ev, ego_vy=vy,
        l1_p=ex + lead_m + _slack(rng, n, 80.0), l1_v=rng.uniform(0.0, 35.0, n),
        l1_decel=np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.0, prm.a_x_d, n)),
        f_p=ex - follow_m - _slack(rng, n, 60.0), f_v=rng.uniform(0.0, 40.0, n), aggressive=rng.random(n) < 0.5,
        l0_p=ex + prm.p_m + _slack(rng, n, 60.0), l0_v=np.where(rng.random(n) < 0.05, 0.0, l0_v),
        l0_decel=np.where(rng.random(n) < 0.3, prm.a_x_d, rng.uniform(0.05, prm.a_x_d, n)),
        lead_margin=lead_m, follow_margin=follow_m, own_margin=np.full(n, prm.p_m),
    )  # fmt: skip


def scene_of(kw: dict, T) -> Scene:
    return Scene(kw["ego_px"], kw["ego_vx"], kw["l1_p"], kw["l1_v"], kw["l1_decel"], kw["l0_p"], kw["l0_v"],
                 kw["l0_decel"], kw["f_p"], kw["f_v"], np.asarray(kw["aggressive"], bool), T)  # fmt: skip


def engine(kw: dict, prm: Params):
    exists, parts = own_lane_core(**kw, prm=prm)
    n = len(kw["ego_px"])
    T = np.broadcast_to(np.asarray(parts["t_y_f"], float), (n,)).copy()
    return exists, parts, T


def margins(kw):
    return kw["lead_margin"], kw["follow_margin"], kw["own_margin"]


def campaign(n_examples: int, body) -> Counter:
    stats = Counter()

    @settings(SETTINGS, max_examples=n_examples)
    @given(seed=SEEDS, kind=KINDS)
    def run(seed, kind):
        rng = np.random.default_rng(seed)
        prm = Params() if kind == "default" else random_params(rng)
        body(rng, prm, stats)

    run()
    return stats


# --------------------------------------------------------------------------------------------------------------
# Soundness
# --------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n_examples", [150, pytest.param(2000, marks=pytest.mark.slow, id="campaign")])
def test_accepted_profiles_keep_every_margin(n_examples, request):
    slow_unless_selected(request, n_examples > 150)

    def body(rng, prm, stats):
        kw = random_states(rng, prm, BATCH)
        exists, parts, T = engine(kw, prm)
        # The lateral horizon is the reference's (outside its 1e-9 m band around "nothing to evade").
        lat = ref_lateral_time(kw["ego_py"], kw["ego_vy"], prm)
        clear = np.abs(lat.peak) > 1e-9
        np.testing.assert_allclose(T[clear], lat.t_y_f[clear], rtol=1e-6, atol=1e-9)
        k = np.where(parts["follows_own"], 0, 1)
        prof = Profile(parts["t_x1"], np.zeros(BATCH), np.full(BATCH, prm.a_x_d), k)
        gaps = profile_gaps(scene_of(kw, T), prof, prm)
        kept = margins_kept(gaps, *margins(kw), T <= 0.0, -SOUND_TOL_M)
        bad = np.flatnonzero(exists & ~kept)
        if bad.size:
            i = bad[0]
            row = {name: float(np.asarray(v)[i]) for name, v in kw.items()}
            raise AssertionError(f"accepted profile breaks a margin: gaps own {gaps.own[i]}, L1 {gaps.l1[i]}, F "
                                 f"{gaps.f[i]}; t_x1 {parts['t_x1'][i]}, follows_own {parts['follows_own'][i]}, "
                                 f"T {T[i]}; inputs {row}; params {prm}")  # fmt: skip
        # The engine's own L0 gap is the reference's minimum (where the verdict is clear of the boundary).
        own = np.flatnonzero(exists & np.isfinite(gaps.own))
        np.testing.assert_allclose(parts["own_gap"][own], gaps.own[own] - kw["own_margin"][own], rtol=1e-6,
                                   atol=1e-6)  # fmt: skip
        evading = T > 0.0
        binds = exists & (gaps.own - kw["own_margin"] < 0.05)
        stats["cases"] += BATCH
        stats["exists"] += int(exists.sum())
        stats["none"] += int((~exists).sum())
        stats["nothing to evade, L0 only"] += int((exists & ~evading).sum())
        stats["follows L0"] += int((exists & parts["follows_own"]).sum())
        stats["L0 binds, evading"] += int((binds & evading).sum())
        stats["L0 binds, u < t_y_f"] += int((binds & evading & (parts["t_x1"] < T - 1e-6) & (parts["t_x1"] > 0)).sum())
        stats["aggressive F, exists"] += int((exists & evading & kw["aggressive"]).sum())

    stats = campaign(n_examples, body)
    print("soundness:", dict(stats))
    assert stats["cases"] >= n_examples * BATCH
    for key in ("exists", "none", "nothing to evade, L0 only", "L0 binds, evading", "L0 binds, u < t_y_f",
                "aggressive F, exists"):  # fmt: skip
        assert stats[key] >= 0.02 * stats["cases"], (key, stats)
    assert stats["follows L0"] >= 10, stats


# --------------------------------------------------------------------------------------------------------------
# Completeness within the family, and the gap to a broader family
# --------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n_examples", [10, pytest.param(100, marks=pytest.mark.slow, id="campaign")])
def test_no_member_of_the_family_is_missed(n_examples, request):
    slow_unless_selected(request, n_examples > 10)

    def body(rng, prm, stats):
        kw = random_states(rng, prm, BATCH)
        exists, _, T = engine(kw, prm)
        rows = np.flatnonzero(~exists)
        sub = {name: np.asarray(v)[rows] for name, v in kw.items()}
        # The engine's bisection may stop up to u_k·2^-16 <= T·2^-16 short of the family's optimum: a grid profile
        # counts as one it must find only if the profile starting to brake T·2^-15 earlier also keeps the margins.
        found, best = family_search(scene_of(sub, T[rows]), g_variants(prm), GRID_N_U, prm, *margins(sub),
                                    COMPLETE_SLACK_M, extra_u_shift=T[rows] * 2.0 ** -(SEARCH_STEPS - 1))  # fmt: skip
        if found.any():
            i = rows[np.argmax(found)]
            row = {name: float(np.asarray(v)[i]) for name, v in kw.items()}
            raise AssertionError(f"G has an evasion (variant {g_variants(prm)[best[np.argmax(found)]]}) the engine "
                                 f"missed: inputs {row}; params {prm}")  # fmt: skip
        stats["cases"] += BATCH
        stats["refuted rows searched"] += rows.size

    stats = campaign(n_examples, body)
    print("completeness:", dict(stats))
    assert stats["refuted rows searched"] >= 0.3 * stats["cases"], stats


@pytest.mark.parametrize("n_examples", [6, pytest.param(120, marks=pytest.mark.slow, id="campaign")])
def test_optimality_gap_to_a_broader_family_is_small(n_examples, request):
    """The share of states where a broader piecewise-constant family (``broad_variants``: softer braking at 0.75 or
    0.5 of ``a_x_d``, holding the speed 0.5–2 s first, braking to rest without following) finds an evasion and ``G``
    does not (a figure for the docs; the 120-example campaign gives it on 7,680 states — measured: 2 states,
    0.03 %, both won by braking at ``a_x_d`` to rest without following, see the xfail case below)."""
    slow_unless_selected(request, n_examples > 6)

    def body(rng, prm, stats):
        kw = random_states(rng, prm, BATCH)
        exists, _, T = engine(kw, prm)
        rows = np.flatnonzero(~exists)
        sub = {name: np.asarray(v)[rows] for name, v in kw.items()}
        found, best = family_search(scene_of(sub, T[rows]), broad_variants(prm), BROAD_N_U, prm, *margins(sub),
                                    COMPLETE_SLACK_M)  # fmt: skip
        stats["cases"] += BATCH
        stats["exists (G)"] += int(exists.sum())
        stats["missed by G"] += int(found.sum())
        for j in best[found]:
            h, b, k = broad_variants(prm)[j]
            stats[f"missed: hold {h} s, brake {b / prm.a_x_d:.2f} a_x_d, follow {['L0', 'L1', 'none'][k]}"] += 1

    stats = campaign(n_examples, body)
    share = stats["missed by G"] / stats["cases"]
    print(f"optimality gap: {stats['missed by G']} of {stats['cases']} states ({100 * share:.2f} %); {dict(stats)}")
    assert share < MAX_GAP_SHARE, stats


# --------------------------------------------------------------------------------------------------------------
# Hand-computed cases (default Params: a_x_a = 2.5, a_x_d = 8, a_y_m = 1.5 m/s², p_m = 7 m, y_s = 0.85 m)
# --------------------------------------------------------------------------------------------------------------


def one_case(**overrides):
    """One state: the ego in its own lane (``y = 0``, ``v_y = 0``: ``t_y_f = 0``) at the origin at 20 m/s; L1 far
    ahead and faster (never constraining), F far behind at rest; L0 filled in by the case; margins p_m."""
    state = dict(ego_px=0.0, ego_py=0.0, ego_vx=20.0, ego_vy=0.0, l1_p=500.0, l1_v=50.0, l1_decel=0.0, f_p=-500.0,
                 f_v=0.0, aggressive=False, l0_p=np.nan, l0_v=20.0, l0_decel=8.0, lead_margin=7.0, follow_margin=7.0,
                 own_margin=7.0)  # fmt: skip
    state.update(overrides)
    return {k: np.atleast_1d(np.asarray(v, bool if k == "aggressive" else float)) for k, v in state.items()}


def verdict(**overrides) -> tuple[bool, dict]:
    exists, parts = own_lane_core(**one_case(**overrides), prm=Params())
    return bool(exists[0]), {k: np.ravel(v)[0] for k, v in parts.items()}


@pytest.mark.parametrize("own_margin", [7.0, 7.0 + 0.5e-9])
def test_equal_speeds_both_braking_hard_keeps_the_gap(own_margin):
    """L0 at the ego's speed braking at ``a_x_d``: the ego brakes at ``a_x_d`` from t = 0 and the gap stays what it
    is; an evasion exists iff the gap is at least ``p_m`` (within the 1e-9 m tolerance)."""
    assert verdict(l0_p=7.01, own_margin=own_margin)[0]
    assert verdict(l0_p=7.0, own_margin=own_margin)[0]
    assert not verdict(l0_p=7.0 - 1e-3, own_margin=own_margin)[0]
    assert not verdict(l0_p=7.0 - 1e-6, own_margin=own_margin)[0]


def test_faster_ego_both_braking_hard_needs_the_stopping_distance_difference():
    """Ego at 20 m/s, L0 at 10 m/s, both braking at ``a_x_d`` = 8: equal decelerations never match speeds, the
    gap shrinks until the ego stops, by the difference of the stopping distances (20² − 10²)/(2·8) = 18.75 m. An
    evasion exists iff the slack beyond ``p_m`` is at least 18.75 m."""
    assert verdict(l0_p=7.0 + 18.75 + 1e-3, l0_v=10.0)[0]
    assert not verdict(l0_p=7.0 + 18.75 - 1e-3, l0_v=10.0)[0]
    _, parts = verdict(l0_p=7.0 + 18.75 + 1e-3, l0_v=10.0)
    assert parts["own_gap"] == pytest.approx(1e-3, abs=1e-9)


def test_faster_ego_behind_a_softer_braking_l0_closes_until_the_speeds_match():
    """Ego at 20 m/s, L0 at 14 m/s braking at 4: the ego brakes at 8, the speeds meet after 6/(8 − 4) = 1.5 s
    (L0 still at 8 m/s), the gap having shrunk by 6²/(2·(8 − 4)) = 4.5 m; after that it follows L0 (or brakes on
    to rest, opening the gap). Exists iff the slack is at least 4.5 m."""
    assert verdict(l0_p=7.0 + 4.5 + 1e-3, l0_v=14.0, l0_decel=4.0)[0]
    assert not verdict(l0_p=7.0 + 4.5 - 1e-3, l0_v=14.0, l0_decel=4.0)[0]
    _, parts = verdict(l0_p=7.0 + 4.5 + 1e-3, l0_v=14.0, l0_decel=4.0)
    assert parts["own_gap"] == pytest.approx(1e-3, abs=1e-9)


def test_l0_caps_the_acceleration_phase_of_an_intruding_ego():
    """The ego intrudes 1 m beyond ``y_s`` at rest laterally (``t_y_f`` = 2·sqrt(1/1.5) = 1.633 s), at 20 m/s; L1
    and F are far away, so the paper's profile would accelerate throughout. L0 at 20 m/s braking at 8: accelerating
    for ``u`` then braking at 8 ends ``20 u + 2.5 u²/2 + ((20 + 2.5 u)² − 20²)/(2·8)`` = 26.25 u + 1.640625 u² further
    than L0 (the gap shrinks until the ego stops), so with a slack of 10.7625 m (u = 0.4 s) the largest ``u`` is
    0.4 s — found by the bisection to within ``t_y_f·2⁻¹⁶``."""
    ok, parts = verdict(ego_py=0.85 + 1.0, l0_p=7.0 + 10.7625, l1_v=30.0, l1_p=200.0, f_p=-100.0)
    assert ok
    assert parts["t_y_f"] == pytest.approx(2.0 * np.sqrt(1.0 / 1.5), rel=1e-9)
    assert parts["t_x1"] <= 0.4 + 1e-9
    assert parts["t_x1"] >= 0.4 - parts["t_y_f"] * 2.0**-SEARCH_STEPS
    assert parts["own_gap"] >= -1e-9 and parts["own_gap"] < 1e-3


KNOWN_GAP_CASE = dict(ego_py=2.1, ego_vx=32.4, ego_vy=1.16, l1_p=15.5, l1_v=25.1, l1_decel=1.8, f_p=-10.0, f_v=13.0,
                      l0_p=7.4, l0_v=32.2, l0_decel=4.2)  # fmt: skip


def test_braking_to_rest_keeps_every_margin_in_the_known_gap_case():
    """The case of the next test, by hand (default Params). Ego at 0, ``y`` 2.1 m moving out at 1.16 m/s (t_y_f ≈
    2.90 s), 32.4 m/s; L1 15.5 m ahead at 25.1 m/s braking at 1.8; L0 7.4 m ahead at 32.2 m/s braking at 4.2; F 10 m
    behind at 13 m/s, collaborative. Braking at 8 to rest from t = 0 keeps every margin: to L0 the ego closes
    0.2²/(2·(8 − 4.2)) = 0.0053 m (min gap 7.3947 m); to L1 7.3²/(2·(8 − 1.8)) = 4.2976 m (min gap 11.2024 m); F only
    falls back (min gap 10 m, at t = 0). Both members of G fail: following L1 (1.8 m/s²) runs into L0 (4.2 m/s²),
    following L0 closes more than L1's slack (checked by the reference)."""
    prm = Params()
    kw = one_case(**KNOWN_GAP_CASE)
    T = np.array([verdict(**KNOWN_GAP_CASE)[1]["t_y_f"]])
    assert T[0] > 2.5
    sc = scene_of(kw, T)
    at_rest = profile_gaps(sc, Profile(np.zeros(1), np.zeros(1), np.full(1, 8.0), np.array([-1])), prm)
    assert at_rest.own[0] == pytest.approx(7.4 - 0.2**2 / (2 * 3.8), abs=1e-9)
    assert at_rest.l1[0] == pytest.approx(15.5 - 7.3**2 / (2 * 6.2), abs=1e-9)
    assert at_rest.f[0] == pytest.approx(10.0, abs=1e-9)
    found, _ = family_search(sc, g_variants(prm), GRID_N_U, prm, *margins(kw), 0.0)
    assert not found[0]


@pytest.mark.xfail(strict=True, reason="optimality gap of G: 'brake at a_x_d to rest' (following nobody) is not a "
                   "member of the family; remove this mark when it is")  # fmt: skip
def test_braking_to_rest_is_an_evasion_when_following_either_leader_is_not():
    """The engine refutes the state of the previous test although braking to rest from t = 0 is a safe evasion."""
    assert verdict(**KNOWN_GAP_CASE)[0]


# --------------------------------------------------------------------------------------------------------------
# Without L0 the shield is bit for bit the paper's
# --------------------------------------------------------------------------------------------------------------


def _world(rng, b: int):
    """Initial states of a hand-written world: ego in its own lane at 20–30 m/s, F 10–30 m behind in the target
    lane, a chain of 3 leaders ahead of it."""
    ego = [np.zeros(b), np.zeros(b), rng.uniform(20.0, 30.0, b), np.zeros(b)]
    f = [-rng.uniform(10.0, 30.0, b), rng.uniform(20.0, 32.0, b)]
    gaps = rng.uniform(10.0, 40.0, (b, 3))
    lx = np.cumsum(gaps, axis=1)
    lv = rng.uniform(18.0, 30.0, (b, 3))
    return ego, f, lx, lv


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    if dataclasses.is_dataclass(a):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@pytest.mark.parametrize(
    "config, sensing",
    [(ShieldConfig(), None), (ShieldConfig(actuation_delay_s=0.2), None), (ShieldConfig(), SensingBounds()),
     (ShieldConfig(own_lane=False), None)],
    ids=["plain", "delay", "sensing", "own_lane_off"],
)  # fmt: skip
@pytest.mark.parametrize("variant", ["CV_all", "CV_none"])
def test_absent_l0_leaves_every_decision_bit_for_bit(config, sensing, variant):
    """Situations without own-lane fields, and the same with ``own_leaders`` all ``+inf`` (K = 1 and K = 2; with
    ``own_lane=False``: a slow L0 20 m ahead, which that shield ignores): every output of every step is equal
    (``np.array_equal``), over 40 periods of a hand-written world where the planner
    pushes the lane change (proposals that get proceeded, hesitated and aborted)."""
    prm = Params()
    b = 48
    rng = np.random.default_rng(17)
    ego, f, lx, lv = _world(rng, b)
    decel = rng.uniform(0.0, 3.0, (b, 3))
    kinds = [None, 1, 2]
    shields = [Shield(prm, variant, config) for _ in kinds]
    behaviours = Counter()
    for step in range(40):
        t = step * prm.dt
        decisions = []
        for kind, shield in zip(kinds, shields, strict=True):
            own = None if kind is None else (np.full((b, kind), np.inf), np.zeros((b, kind)))
            if kind is not None and not config.own_lane:  # the paper's shield ignores an L0 that is there
                own = (ego[0][:, None] + 20.0 * np.arange(1, kind + 1), np.full((b, kind), 5.0))
            sit = Situation.from_arrays(t=t, ego=tuple(ego), follower=tuple(f), leaders=(lx, lv), n_connected=2,
                                        own_leaders=own, sensing=sensing, params=prm)  # fmt: skip
            if step == 0:
                shield.reset(sit)
            decisions.append(shield.step(sit, (np.full(b, 1.0), np.full(b, 1.5))))
        for other in decisions[1:]:
            for field in dataclasses.fields(other):
                name = "plan" if field.name == "_plan" else field.name  # (a Decision's plan: built when read)
                assert _same(getattr(decisions[0], name), getattr(other, name)), (step, name)
        for other in shields[1:]:
            assert _same(shields[0].state, other.state), step
        d = decisions[0]
        behaviours.update(d.behaviour.tolist())
        # The world: the ego as commanded (stopping, not reversing), F and the leaders braking gently.
        ego[0] = ego[0] + ego[2] * prm.dt + 0.5 * d.a_x * prm.dt**2
        ego[2] = np.maximum(ego[2] + d.a_x * prm.dt, 0.0)
        ego[1] = ego[1] + ego[3] * prm.dt + 0.5 * d.a_y * prm.dt**2
        ego[3] = ego[3] + d.a_y * prm.dt
        f[0] = f[0] + f[1] * prm.dt
        lx = lx + lv * prm.dt
        lv = np.maximum(lv - decel * prm.dt, 0.0)
    assert len(behaviours) >= 3, behaviours  # proceed, and at least two of hesitate / abort / completed
