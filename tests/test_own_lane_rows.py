"""The own-lane check one row at a time, uncompiled: the row backend (``SCALAR``) skips work the array path computes
and discards — the gaps that ``nothing`` (no lateral evasion) voids, the gaps at ``u_k`` where ``u = 0`` already
breaks a leader, the gaps at a member's switch time already taken (``own_lane.known_gaps``), ``L0``'s member where
``L1``'s evades — and must give the array path's bits all the same.

``shield/_fast_own._member``'s Python function (``py_func``: the closed forms on Python floats, no numba) per row and
member, then ``choose_member``, against :func:`~safelane.safety.own_lane.own_lane_core` on the whole batch; and
:func:`~safelane.safety.own_lane.leaders_gap` and :func:`~safelane.safety.own_lane.member_parts` on rows with and
without anything to evade. ``tests/test_fast_own.py`` compares the compiled rows the same way; this file runs where
mutation testing runs (``SAFELANE_NO_NUMBA=1``), so that what only a row does is tested there too.
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.safety import own_lane
from safelane.safety._backend import ARRAY, SCALAR
from safelane.safety.lateral import lateral_core
from test_own_lane import random_params, random_states

N = 160


def _bits(a) -> np.ndarray:
    a = np.asarray(a)
    return a.astype(np.float64).view(np.uint64) if a.dtype.kind == "f" else a.astype(np.int64)


def _same(name: str, got, want) -> None:
    want = np.broadcast_to(want, np.shape(got))
    got, want = _bits(np.asarray(got, dtype=want.dtype)), _bits(want)
    bad = np.flatnonzero(got != want)
    assert bad.size == 0, f"{name}: rows {bad[:5]} differ"


def _rows(seed: int):
    rng = np.random.default_rng(300 + seed)
    prm = Params() if seed % 2 == 0 else random_params(rng)
    kw = random_states(rng, prm, N)
    return prm, kw


@pytest.mark.parametrize("seed", range(4))
def test_the_rows_members_give_the_arrays_bits(seed):
    pytest.importorskip("numba")  # (the row function's module imports numba; it runs uncompiled here all the same)
    from safelane.shield._fast_own import _member

    prm, kw = _rows(seed)
    with np.errstate(all="ignore"):
        exists, parts = own_lane.own_lane_core(**kw, prm=prm)
    tol = own_lane.FEASIBILITY_TOL_M
    row = _member.py_func  # the row function uncompiled: the closed forms on Python floats
    got = {name: np.empty(N) for name in own_lane.CHOSEN}
    got_exists, got_own = np.empty(N, bool), np.empty(N, bool)
    skipped = 0
    for i in range(N):
        r = {k: (bool(v[i]) if k == "aggressive" else float(v[i])) for k, v in kw.items()}
        T = lateral_core(SCALAR, r["ego_py"], r["ego_vy"], prm)[0]
        nothing = T <= 0.0
        l1, l0 = (r["l1_p"], r["l1_v"], r["l1_decel"]), (r["l0_p"], r["l0_v"], r["l0_decel"])
        common = (T, nothing, r["lead_margin"], r["own_margin"])
        tail = (r["f_p"], r["f_v"], r["aggressive"], r["follow_margin"], prm, tol)
        via_l1 = row(r["ego_px"], r["ego_vx"], l1, l0, l1, *common, r["lead_margin"], *tail)
        via_l0 = via_l1 if via_l1[0] else row(r["ego_px"], r["ego_vx"], l0, l0, l1, *common, r["own_margin"], *tail)
        skipped += bool(via_l1[0])
        chosen = own_lane.choose_member(SCALAR, via_l1, via_l0)
        got_exists[i], got_own[i] = chosen[0], chosen[1]
        for name, value in zip(own_lane.CHOSEN, chosen[2:], strict=True):
            got[name][i] = value
    _same("exists", got_exists, exists)
    _same("follows_own", got_own, parts["follows_own"])
    for name in own_lane.CHOSEN:
        _same(name, got[name], parts[name])
    assert 0 < skipped < N and parts["nothing"].any() and not parts["nothing"].all()


@pytest.mark.parametrize("seed", range(3))
def test_leaders_gap_and_member_parts_of_a_row_give_the_arrays_bits(seed):
    prm, kw = _rows(10 + seed)
    rng = np.random.default_rng(seed)
    p, v = kw["ego_px"], kw["ego_vx"]
    l1 = (kw["l1_p"], kw["l1_v"], kw["l1_decel"])
    l0 = (kw["l0_p"], kw["l0_v"], kw["l0_decel"])
    T = np.where(rng.random(N) < 0.4, 0.0, rng.uniform(0.2, 6.0, N))
    nothing = T <= 0.0
    u = rng.uniform(0.0, 1.2, N) * T
    lm, om, tol = kw["lead_margin"], kw["own_margin"], own_lane.FEASIBILITY_TOL_M
    with np.errstate(all="ignore"):
        gaps = own_lane.leaders_gap(ARRAY, u, p, v, l1, l0, l1, T, nothing, lm, om, prm)
        g_lo = gaps[0] + rng.choice([0.0, 1.0, -1.0], N)  # u kept or set to 0 by member_parts, both sides
        member = own_lane.member_parts(ARRAY, u, g_lo, gaps, p, v, l1, T, nothing, kw["f_p"], kw["f_v"],
                                       kw["aggressive"], kw["follow_margin"], prm, tol)  # fmt: skip

    def at(a, i):
        return a[i] if np.ndim(a) else a

    for i in range(N):
        lead = tuple(float(a[i]) for a in l1)
        other = tuple(float(a[i]) for a in l0)
        row_gaps = own_lane.leaders_gap(SCALAR, float(u[i]), float(p[i]), float(v[i]), lead, other, lead, float(T[i]),
                                        bool(nothing[i]), float(lm[i]), float(om[i]), prm)  # fmt: skip
        for name, got, want in zip(("g", "g1", "g0"), row_gaps, gaps, strict=True):
            _same(f"leaders_gap {name} row {i}", np.float64(got), at(want, i))
        row_member = own_lane.member_parts(
            SCALAR, float(u[i]), float(g_lo[i]), tuple(float(at(g, i)) for g in gaps), float(p[i]), float(v[i]), lead,
            float(T[i]), bool(nothing[i]), float(kw["f_p"][i]), float(kw["f_v"][i]), bool(kw["aggressive"][i]),
            float(kw["follow_margin"][i]), prm, tol,
        )  # fmt: skip
        for name, got, want in zip(own_lane.MEMBER, row_member, member, strict=True):
            _same(f"member_parts {name} row {i}", np.asarray(got), at(want, i))
    assert nothing.any() and not nothing.all()


@pytest.mark.parametrize("seed", range(3))
def test_the_gaps_reported_are_those_at_the_reported_switch_time(seed):
    """What ``own_lane_core`` reports for the chosen member — ``lead_gap`` (to ``L1`` over ``[0, T]``) and ``own_gap``
    (to ``L0`` over ``[0, ∞)``) — is :func:`~safelane.safety.own_lane.leaders_gap` taken afresh at the switch time it
    reports (``t_x1``) for the leader it follows: whether the gaps were taken there, at ``u_k`` or at ``u = 0`` before
    (``known_gaps``), or after a bisection."""
    rng = np.random.default_rng(40 + seed)
    prm = Params()
    kw = random_states(rng, prm, 4000)
    # A quarter at a knife edge: L0 at its margin plus less than the tolerance, as fast as the ego, braking softer
    # than it can: the gap at u = 0 is within the tolerance above 0 and any acceleration breaks it, so the
    # bisection runs and ends at a small u > 0, whose gaps are not those at 0
    knife = np.arange(0, 4000, 4)
    kw["l0_p"][knife] = kw["ego_px"][knife] + kw["own_margin"][knife] + rng.uniform(1e-10, 9e-10, knife.size)
    kw["l0_v"][knife] = kw["ego_vx"][knife]
    kw["l0_decel"][knife] = rng.uniform(0.5, prm.a_x_d - 0.5, knife.size)
    searched = []
    real_search = own_lane._search

    def search(xp, u_hi, *args):
        searched.append(np.size(u_hi))
        return real_search(xp, u_hi, *args)

    own_lane._search = search
    try:
        with np.errstate(all="ignore"):
            exists, parts = own_lane.own_lane_core(**kw, prm=prm)
    finally:
        own_lane._search = real_search
    T = np.broadcast_to(parts["t_y_f"], exists.shape)
    own = parts["follows_own"]
    l1 = (kw["l1_p"], kw["l1_v"], kw["l1_decel"])
    l0 = (kw["l0_p"], kw["l0_v"], kw["l0_decel"])
    lead = tuple(np.where(own, b, a) for a, b in zip(l1, l0, strict=True))
    with np.errstate(all="ignore"):
        _, g1, g0 = own_lane.leaders_gap(ARRAY, parts["t_x1"], kw["ego_px"], kw["ego_vx"], lead, l0, l1, T, T <= 0.0,
                                         kw["lead_margin"], kw["own_margin"], prm)  # fmt: skip
    _same("lead_gap", parts["lead_gap"], g1)
    _same("own_gap", parts["own_gap"], g0)
    assert sum(searched) > 20, sum(searched)
