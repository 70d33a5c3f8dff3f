"""The compiled plan kernel (:func:`safelane.safety._fast.plan_kernel`, numba) against ``evasion_core``'s NumPy path.

``evasion_core`` runs the kernel for NumPy batches of ``FAST_PLAN_MIN`` elements or more; the shield's every
candidate check goes through it. Every output — the verdict and all fourteen fields of the plan's parts — must be
the NumPy path's, bit for bit, on random states and on the knife edges of ``test_fast_core`` (gaps exactly at the
margin, equal speeds, equal decelerations, stopped vehicles, the ego on ``y_s`` or returning onto it), in batches
where some or all rows have nothing to evade (the NumPy path's shortcuts), with broadcast scalar arguments.
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.safety import evasion as ev
from safelane.safety._backend import ARRAY
from test_fast_core import _cases, _inputs, _same_bits, knife_edges, needs_numba
from test_safety_shapes import evasion_inputs

# A compiled kernel against the uncompiled path (tests/conftest.py: skipped while mutation testing mutates them).
pytestmark = pytest.mark.compiled

PARAMS = Params()


def _both(monkeypatch, args, tol=ev.FEASIBILITY_TOL_M):
    """``(kernel, numpy)``: evasion_core's ``(exists, parts)`` with and without the kernel."""
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    with np.errstate(all="ignore"):
        fast = ev.evasion_core(ARRAY, *args, PARAMS, tol)
        monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
        slow = ev.evasion_core(ARRAY, *args, PARAMS, tol)
    monkeypatch.delenv("SAFELANE_NO_NUMBA")
    return fast, slow


def _assert_same(fast, slow, name):
    (exists_f, parts_f), (exists_s, parts_s) = fast, slow
    np.testing.assert_array_equal(exists_f, exists_s, err_msg=name)
    assert set(parts_f) == set(parts_s)
    for key, value in parts_s.items():
        value = np.broadcast_to(value, np.shape(exists_s))
        got = parts_f[key]
        assert got.shape == value.shape, f"{name}: {key} has shape {got.shape}, not {value.shape}"
        assert got.dtype == np.asarray(value).dtype, f"{name}: {key} is {got.dtype}, not {value.dtype}"
        same = _same_bits(got, value) if got.dtype.kind == "f" else got == value
        assert same.all(), f"{name}: {key} differs at {np.flatnonzero(~same)[:5]}"


@needs_numba
@pytest.mark.parametrize("name,states,human", _cases(23, 30_000), ids=lambda x: x if isinstance(x, str) else "")
def test_plan_kernel_gives_every_part_bit_for_bit(name, states, human, monkeypatch):
    args = _inputs(states, human)
    fast, slow = _both(monkeypatch, args)
    _assert_same(fast, slow, name)
    exists, parts = slow
    # the comparison means something: both verdicts, every lateral case, leader-following and not, both reasons
    assert 0.05 < exists.mean() < 0.95
    assert parts["nothing"].any() and not parts["nothing"].all()
    assert (parts["y_acc_1"] < 0).any() and (parts["t_y_switch"] == 0).any()
    assert parts["follows_leader"].any() and not parts["follows_leader"].all()
    assert (~parts["lead_ok"]).any() and (parts["lead_ok"] & ~parts["follow_ok"]).any()
    # a looser tolerance changes verdicts, and the kernel follows it
    loose = _both(monkeypatch, args, tol=0.05)
    _assert_same(*loose, f"{name}, tol 0.05")
    assert (loose[1][0] != exists).any()


@needs_numba
def test_plan_kernel_on_rows_with_nothing_to_evade(monkeypatch):
    # all rows idle (the NumPy path's shortcut: one candidate), and a batch that mixes idle rows in
    s = knife_edges(np.random.default_rng(24), 4000)
    s["ego_py"] = np.full(4000, PARAMS.y_safe - 0.5)
    s["ego_vy"] = np.where(np.arange(4000) % 2 == 0, 0.0, -0.3)
    idle = _inputs(s, (False, False))
    fast, slow = _both(monkeypatch, idle)
    assert slow[1]["nothing"].all() and slow[0].all()
    _assert_same(fast, slow, "all idle")
    mixed = knife_edges(np.random.default_rng(25), 4000)
    for key in ("ego_py", "ego_vy"):
        mixed[key] = np.where(np.arange(4000) % 3 == 0, s[key], mixed[key])
    fast, slow = _both(monkeypatch, _inputs(mixed, (False, False)))
    assert slow[1]["nothing"].any() and not slow[1]["nothing"].all()
    _assert_same(fast, slow, "mixed")


@needs_numba
def test_plan_kernel_broadcasts_scalars_and_plan_evasion_agrees(monkeypatch):
    s = knife_edges(np.random.default_rng(26), 600)
    args = list(_inputs(s, (False, False)))
    args[6] = np.float64(PARAMS.a_x_d)  # L1 at a_x_d everywhere: a 0-d argument
    args[10] = PARAMS.p_m  # the margins as plain floats, as the shield passes them
    args[11] = PARAMS.p_m
    _assert_same(*_both(monkeypatch, tuple(args)), "broadcast")
    # through the public plan_evasion (validation, then the core): every field of the plan
    keys = [*ev._PLAN_INPUTS, "follower_aggressive"]
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    fast = ev.plan_evasion(*(s[k] for k in keys), PARAMS)
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    slow = ev.plan_evasion(*(s[k] for k in keys), PARAMS)
    for field in ("feasible", "reason", "t_y_f", "t_x1", "t_x2", "min_gap_leader", "min_gap_follower", "v_switch"):
        a, b = getattr(fast, field), getattr(slow, field)
        assert (_same_bits(a, b) if a.dtype.kind == "f" else a == b).all(), field


@needs_numba
def test_the_kernel_runs_from_its_threshold_and_not_below(monkeypatch):
    from safelane.safety import _fast

    calls = []
    real = _fast.run_plan
    monkeypatch.setattr(_fast, "run_plan", lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    monkeypatch.delenv("SAFELANE_NO_NUMBA", raising=False)
    rng = np.random.default_rng(27)
    for n in (ev.FAST_PLAN_MIN - 1, ev.FAST_PLAN_MIN):
        with np.errstate(all="ignore"):
            ev.evasion_core(ARRAY, *_inputs(evasion_inputs(rng, (n,)), (False, False)), PARAMS)
    assert calls == [(ev.FAST_PLAN_MIN,)]
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    with np.errstate(all="ignore"):
        ev.evasion_core(ARRAY, *_inputs(evasion_inputs(rng, (100,)), (False, False)), PARAMS)
    assert len(calls) == 1  # the switch keeps the NumPy path
