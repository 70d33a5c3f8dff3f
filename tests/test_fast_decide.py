"""The compiled candidate check (:mod:`safelane.shield._fast_decide`, numba) against ``decide.check_candidate``'s NumPy
path: the verdict, the completing rows and every field of every accepted plan, bit for bit, for each registered
completion rule, on ``test_decide``'s state families (near the lane boundary, gaps just outside ``p_m`` that dip
inside within the period) and on states with nothing to evade. Rows with an own-lane leader keep the NumPy path."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane import Params
from safelane.shield import decide
from safelane.shield.policies import COMPLETION_RULES
from test_decide import ORDER, _follower_dip_states, _leader_dip_states, _states
from test_fast_core import needs_numba

# A compiled kernel against the uncompiled path (tests/conftest.py: skipped while mutation testing mutates them).
pytestmark = pytest.mark.compiled

PRM = Params()


def _knife_states(n: int, rng) -> dict:
    """Knife edges of the candidate check: the lateral peak inside the period just above or below ``y_s`` (the
    conflict zone decided by the period's vertex, not its ends), and gaps exactly at ``p_m`` with F closing in."""
    s = _states(n, rng)
    a_y = -rng.uniform(0.5, 1.0, n) * PRM.a_y_m
    vy = rng.uniform(0.0, 0.09, n) * -a_y  # lateral speed reaches 0 inside the period
    rise = vy * vy / (2.0 * -a_y)
    s["a_y"], s["ego_vy"] = a_y, vy
    s["ego_y"] = PRM.y_safe - rise * rng.uniform(0.0, 2.0, n)
    at_margin = rng.random(n) < 0.5
    s["f_x"] = np.where(at_margin, s["ego_x"] - PRM.p_m, s["f_x"])
    s["f_v"] = np.where(at_margin, s["ego_vx"] + rng.uniform(-0.5, 0.5, n), s["f_v"])  # closing in or not
    s["f_aggressive"] = np.where(at_margin, rng.random(n) < 0.5, s["f_aggressive"])
    s["l1_x"] = np.where(~at_margin & (rng.random(n) < 0.5), s["ego_x"] + PRM.p_m, s["l1_x"])
    return s


def _verdicts(monkeypatch, s, completion):
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = decide.check_candidate(*(s[k] for k in ORDER), PRM, completion=completion)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    slow = decide.check_candidate(*(s[k] for k in ORDER), PRM, completion=completion)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    return fast, slow


def _by_row(verdict) -> dict:
    """``{row: {field: value}}`` over the verdict's plans."""
    out = {}
    for rows, plan in verdict.plans:
        for j, r in enumerate(rows):
            out[int(r)] = {f.name: np.asarray(getattr(plan, f.name))[j] for f in dataclasses.fields(plan)
                           if isinstance(getattr(plan, f.name), np.ndarray)}  # fmt: skip
    return out


def _assert_same(fast, slow):
    np.testing.assert_array_equal(fast.ok, slow.ok)
    np.testing.assert_array_equal(fast.completing, slow.completing)
    a, b = _by_row(fast), _by_row(slow)
    assert sorted(a) == sorted(b) == list(np.flatnonzero(slow.ok))
    for row, fields in b.items():
        assert a[row].keys() == fields.keys()
        for name, value in fields.items():
            got = a[row][name]
            same = got == value or (np.isnan(got) and np.isnan(value)) if value.dtype.kind == "f" else got == value
            assert same, f"row {row}: {name} {got!r} != {value!r}"


@needs_numba
@pytest.mark.parametrize("rule", sorted(COMPLETION_RULES))
@pytest.mark.parametrize(
    "family", [_states, _follower_dip_states, _leader_dip_states, _knife_states], ids=lambda f: f.__name__
)
def test_the_kernel_gives_the_numpy_paths_verdicts_and_plans(monkeypatch, rule, family):
    completion = COMPLETION_RULES[rule]
    s = family(2500, np.random.default_rng(sorted(COMPLETION_RULES).index(rule)))
    if hasattr(completion, "level") and family is _states:  # its crossing level higher: the states move up
        s["ego_y"] = s["ego_y"] + (completion.level(PRM) - PRM.y_boundary)
    fast, slow = _verdicts(monkeypatch, s, completion)
    _assert_same(fast, slow)
    assert 0 < slow.ok.sum() < len(slow.ok)  # both verdicts occur
    if family is _states:
        assert slow.completing.any() and (slow.ok & slow.completing).any()
    if family is _knife_states:  # rows whose conflict is the vertex's alone, and rejected ones among them
        y, vy, a_y = s["ego_y"], s["ego_vy"], s["a_y"]
        end = y + vy * PRM.dt + 0.5 * a_y * PRM.dt**2
        line = PRM.y_safe + 1e-9
        vertex_only = (np.maximum(y, end) <= line) & (y + vy * vy / (2.0 * -a_y) > line)
        assert vertex_only.sum() > 100 and (vertex_only & ~slow.ok).sum() > 20


@needs_numba
def test_rows_with_nothing_to_evade_and_a_rule_of_the_users(monkeypatch):
    s = _states(600, np.random.default_rng(9))
    s["ego_y"] = np.where(np.arange(600) % 2 == 0, 0.0, s["ego_y"])  # in the own lane
    s["ego_vy"] = np.where(np.arange(600) % 2 == 0, -0.1, s["ego_vy"])

    def strict(ex, evx, lx, lv, l1_decel, fx, fv, prm):  # a user's completion rule: 10 m of room both ways
        return (lx - ex >= 10.0) & (ex - fx >= 10.0)

    strict.needs_evasion = True
    strict.level = lambda prm: prm.y_boundary - 0.2
    fast, slow = _verdicts(monkeypatch, s, strict)
    _assert_same(fast, slow)
    assert slow.completing.any() and (slow.completing & ~slow.ok).any()


@needs_numba
def test_the_kernel_runs_from_its_threshold_and_not_with_an_own_lane_leader(monkeypatch):
    from safelane.shield import _fast_decide

    calls = []
    real = _fast_decide.check_candidate
    monkeypatch.setattr(_fast_decide, "check_candidate", lambda *a: calls.append(len(a[0])) or real(*a))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    for n in (decide.FAST_CANDIDATE_MIN - 1, decide.FAST_CANDIDATE_MIN):
        s = _states(n, np.random.default_rng(n))
        decide.check_candidate(*(s[k] for k in ORDER), PRM)
    assert calls == [decide.FAST_CANDIDATE_MIN]
    s = _states(100, np.random.default_rng(3))
    own = (s["ego_x"] + 50.0, s["ego_vx"], np.full(100, PRM.a_x_d))
    decide.check_candidate(*(s[k] for k in ORDER), PRM, own=own)
    assert len(calls) == 1
