"""The compiled candidate check with an own-lane leader ``L0`` (:mod:`safelane.shield._fast_own`, numba) against the
NumPy path, bit for bit: every output of ``decide._with_own``'s NumPy block — the predicted states, the period's
verdict with ``L0``'s gap over it, completion, ``L0``'s worst case at the period's end, and every part of
``own_lane_core``'s check — as ``decide.verdict_of`` receives it, for each registered completion rule, on L0 braking,
standing, far away and at knife edges at ``p_m``; and ``own_lane_core`` itself (the kernel ``own_lane_kernel``) on
``test_own_lane``'s random states under random parameters. Bits, not values: a float is compared through its 64-bit
pattern (``-0.0`` differs from ``0.0``, a NaN must be the same NaN)."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.safety import own_lane
from safelane.shield import decide
from safelane.shield.policies import COMPLETION_RULES
from test_decide import ORDER, _states
from test_fast_core import needs_numba
from test_own_lane import random_params, random_states

# A compiled kernel against the uncompiled path (tests/conftest.py: skipped while mutation testing mutates them).
pytestmark = pytest.mark.compiled

PRM = Params()
N = 2000


def _l0_braking(s: dict, rng) -> tuple:
    """L0 close ahead (a centimetre to 60 m beyond ``p_m``, some inside it) at about the ego's speed, braking at up to
    ``a_x_d`` (a third exactly at it)."""
    n = len(s["ego_x"])
    slack = np.where(rng.random(n) < 0.5, np.exp(rng.uniform(np.log(1e-2), np.log(60.0), n)), rng.uniform(-1.0, 20, n))
    v = np.maximum(s["ego_vx"] + rng.normal(0.0, 3.0, n), 0.0)
    decel = np.where(rng.random(n) < 1 / 3, PRM.a_x_d, rng.uniform(0.05, PRM.a_x_d, n))
    return s["ego_x"] + PRM.p_m + slack, v, decel


def _l0_standing(s: dict, rng) -> tuple:
    """L0 at rest, from just beyond ``p_m`` to 80 m ahead."""
    n = len(s["ego_x"])
    return s["ego_x"] + PRM.p_m + rng.uniform(0.0, 80.0, n) ** 2 / 80.0, np.zeros(n), np.full(n, PRM.a_x_d)


def _l0_far(s: dict, rng) -> tuple:
    """L0 200 m to 2 km ahead, at any speed and braking."""
    n = len(s["ego_x"])
    return s["ego_x"] + rng.uniform(200.0, 2000.0, n), rng.uniform(0.0, 40.0, n), rng.uniform(0.0, PRM.a_x_d, n)


def _l0_knife(s: dict, rng) -> tuple:
    """Knife edges at ``p_m``: L0 exactly at the margin or within a few nanometres to a millimetre of it, at the
    ego's speed, braking at ``a_x_d`` (the ego's committed braking: following it keeps the gap exactly) or a little
    less; the ego's own acceleration over the period at its bounds or zero for half of the rows."""
    n = len(s["ego_x"])
    offset = rng.choice([0.0, 1e-9, -1e-9, 5e-10, -5e-10, 1e-6, -1e-6, 1e-3], n)
    decel = np.where(rng.random(n) < 0.7, PRM.a_x_d, PRM.a_x_d - rng.uniform(0.0, 0.5, n))
    s["a_x"] = np.where(rng.random(n) < 0.5, rng.choice([-PRM.a_x_d, 0.0, PRM.a_x_a], n), s["a_x"])
    return s["ego_x"] + PRM.p_m + offset, s["ego_vx"].copy(), decel


def _l0_mixed(s: dict, rng) -> tuple:
    """A third of the rows without L0 (``+inf``), the others braking close ahead."""
    x, v, decel = _l0_braking(s, rng)
    return np.where(rng.random(len(x)) < 1 / 3, np.inf, x), v, decel


FAMILIES = (_l0_braking, _l0_standing, _l0_far, _l0_knife, _l0_mixed)


def _bits(a) -> np.ndarray:
    a = np.ascontiguousarray(a)
    return a.view(np.int64) if a.dtype == np.float64 else a


def _assert_bits(name: str, got, want) -> None:
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape and got.dtype == want.dtype, (name, got.shape, want.shape, got.dtype, want.dtype)
    differ = np.flatnonzero(_bits(got) != _bits(want))
    assert differ.size == 0, f"{name}: {differ.size} rows differ, e.g. row {differ[0]}: {got[differ[0]]!r} != " \
                             f"{want[differ[0]]!r}"  # fmt: skip


def _numpy_block(monkeypatch, s: dict, own: tuple, completion) -> tuple[dict, int]:
    """What ``decide._with_own``'s NumPy block hands ``verdict_of`` for the rows with L0 (``SAFELANE_NO_NUMBA=1``), and
    how many of those rows' members ran the bisection."""
    seen, searched = {}, []
    real_verdict, real_search = decide.verdict_of, own_lane._search

    def record(state, period_ok, completing, exists, parts, *rest, own=None):
        if own is not None:
            seen.update(state=state, period_ok=period_ok, completing=completing, exists=exists, parts=parts, own=own)
        return real_verdict(state, period_ok, completing, exists, parts, *rest, own=own)

    def count(xp, u_hi, *args):
        searched.append(np.size(u_hi))
        return real_search(xp, u_hi, *args)

    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    monkeypatch.setattr(decide, "verdict_of", record)
    monkeypatch.setattr(own_lane, "_search", count)
    decide.check_candidate(*(s[k] for k in ORDER), PRM, completion=completion, own=own)
    monkeypatch.undo()
    return seen, sum(searched)


@needs_numba
@pytest.mark.parametrize("rule", sorted(COMPLETION_RULES))
@pytest.mark.parametrize("family", FAMILIES, ids=lambda f: f.__name__)
def test_the_kernel_gives_the_numpy_blocks_bits(monkeypatch, rule, family):
    from safelane.shield import _fast_own

    rng = np.random.default_rng([FAMILIES.index(family), sorted(COMPLETION_RULES).index(rule)])
    s = _states(N, rng)
    own = family(s, rng)
    completion = COMPLETION_RULES[rule]
    want, searched = _numpy_block(monkeypatch, s, own, completion)
    rows = np.flatnonzero(np.isfinite(own[0]))
    level = max(decide.own_completion_level(PRM), decide.completion_level(completion, PRM))
    state, period_ok, completing, (l0_x, l0_v), exists, parts = _fast_own.check_own(
        tuple(s[k][rows] for k in ORDER), tuple(a[rows] for a in own), PRM, level
    )
    for j, name in enumerate(_fast_own.STATES[:8]):
        _assert_bits(name, state[j], want["state"][j])
    _assert_bits("period_ok", period_ok, want["period_ok"])
    _assert_bits("completing", completing, want["completing"])
    _assert_bits("l0_x", l0_x, want["own"][0])
    _assert_bits("l0_v", l0_v, want["own"][1])
    _assert_bits("exists", exists, want["exists"])
    assert parts.keys() == want["parts"].keys()
    for name, value in want["parts"].items():
        _assert_bits(name, parts[name], np.broadcast_to(value, rows.shape))
    # Not vacuous: both verdicts of the period and of the evasion occur, and where L0 is close the search runs.
    assert 0 < period_ok.sum() < rows.size and 0 < exists.sum() < rows.size
    if family in (_l0_braking, _l0_mixed):
        assert searched > 20, searched


@needs_numba
@pytest.mark.parametrize("seed", range(6))
def test_own_lane_rows_give_own_lane_cores_bits(monkeypatch, seed):
    from safelane.shield import _fast_own

    rng = np.random.default_rng(100 + seed)
    prm = PRM if seed % 2 == 0 else random_params(rng)
    kw = random_states(rng, prm, N)
    searched = []
    real_search = own_lane._search
    monkeypatch.setattr(own_lane, "_search", lambda xp, u_hi, *a: searched.append(np.size(u_hi)) or real_search(
        xp, u_hi, *a))  # fmt: skip
    with np.errstate(all="ignore"):
        want_exists, want = own_lane.own_lane_core(**kw, prm=prm)
    monkeypatch.undo()
    exists, parts = _fast_own.own_lane_rows(**kw, prm=prm)
    _assert_bits("exists", exists, want_exists)
    assert parts.keys() == want.keys()
    for name, value in want.items():
        _assert_bits(name, parts[name], np.broadcast_to(value, (N,)))
    assert sum(searched) > 100 and 0 < exists.sum() < N
    assert parts["follows_own"].any() and (parts["follows_own"] & exists).any()


@needs_numba
@pytest.mark.parametrize("family", FAMILIES, ids=lambda f: f.__name__)
def test_check_candidate_dispatches_the_l0_rows_to_the_kernel_with_the_same_verdicts_and_plans(monkeypatch, family):
    """Where ``decide`` dispatches the rows with L0 to this kernel (``decide.own_kernel``): the whole
    ``check_candidate`` — verdicts, completing rows, every field of every plan — is the NumPy path's, and the kernel
    ran."""
    from safelane.shield import _fast_own
    from test_fast_decide import _assert_same

    if not hasattr(decide, "own_kernel"):
        pytest.skip("decide.check_candidate does not dispatch the rows with L0 to shield/_fast_own yet")
    rng = np.random.default_rng([7, FAMILIES.index(family)])
    s = _states(N, rng)
    own = family(s, rng)
    calls = []
    real = _fast_own.check_own
    monkeypatch.setattr(_fast_own, "check_own", lambda *a: calls.append(len(a[0][0])) or real(*a))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = decide.check_candidate(*(s[k] for k in ORDER), PRM, own=own)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    slow = decide.check_candidate(*(s[k] for k in ORDER), PRM, own=own)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    assert calls == [np.isfinite(own[0]).sum()]
    _assert_same(fast, slow)
    assert 0 < slow.ok.sum() < N
