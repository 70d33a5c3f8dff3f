"""The proposal check (``shield/proposals.py``) and the shield's answer (``shield/decision.py``) as units.

The rules are the module docstrings': a proposal is a pair of ``(B,)`` number arrays (anything else is a programming
error naming the planner); a finite action inside the mechanical limits, to ``1e-9`` m/s², is valid; an invalid row
holds ``0`` in both components. A :class:`Decision` intervenes where it hesitates, aborts or met an invalid proposal,
and gives one readable reason per row.
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.shield import ABORT, BREACH_KINDS, COMPLETED, HESITATE, PROCEED, Breach, Decision
from safelane.shield.proposals import check_proposal

PRM = Params()


def _reference(a_x, a_y, prm=PRM, tol=1e-9):
    """Validity row by row in plain Python floats (the module docstring's rule)."""
    out = []
    for x, y in zip(a_x, a_y, strict=True):
        finite = np.isfinite(x) and np.isfinite(y)
        out.append(
            bool(finite and -prm.a_x_d - tol <= x <= prm.a_x_a + tol and -prm.a_y_m - tol <= y <= prm.a_y_m + tol)
        )
    return np.array(out)


def test_validity_and_zeroed_rows_match_the_rule_on_edges_and_random_values():
    """Exact limits, just inside the 1e-9 tolerance, just outside it, non-finite values in either component."""
    inside, outside = 0.5e-9, 2e-9
    xs = [0.0, PRM.a_x_a, -PRM.a_x_d, PRM.a_x_a + inside, -PRM.a_x_d - inside, PRM.a_x_a + outside,
          -PRM.a_x_d - outside, np.nan, np.inf, -np.inf, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]  # fmt: skip
    ys = [0.0] * 10 + [PRM.a_y_m, -PRM.a_y_m, PRM.a_y_m + inside, -PRM.a_y_m - inside, PRM.a_y_m + outside,
                       -PRM.a_y_m - outside, np.nan, np.inf, -np.inf, 0.3]  # fmt: skip
    rng = np.random.default_rng(18)
    xs += list(rng.uniform(-12.0, 5.0, 200))
    ys += list(rng.uniform(-2.5, 2.5, 200))
    a_x, a_y = np.array(xs), np.array(ys)
    out_x, out_y, invalid = check_proposal("p", (a_x, a_y), len(a_x), PRM)
    expected_ok = _reference(a_x, a_y)
    assert expected_ok[:5].all() and not expected_ok[5:10].any() and expected_ok[10:14].all()
    assert not expected_ok[14:19].any() and expected_ok[19]
    assert 0 < expected_ok[20:].sum() < 200
    np.testing.assert_array_equal(invalid, ~expected_ok)
    np.testing.assert_array_equal(out_x, np.where(expected_ok, a_x, 0.0))
    np.testing.assert_array_equal(out_y, np.where(expected_ok, a_y, 0.0))
    assert out_x.dtype == float and out_y.dtype == float and invalid.dtype == bool


def test_other_params_move_the_limits():
    prm = Params(a_x_a=1.0, a_x_d=3.0, a_y_m=0.5)
    a_x = np.array([1.0, 1.1, -3.0, -3.1, 0.0, 0.0])
    a_y = np.array([0.0, 0.0, 0.0, 0.0, -0.5, 0.6])
    _, _, invalid = check_proposal("p", (a_x, a_y), 6, prm)
    np.testing.assert_array_equal(invalid, [False, True, False, True, False, True])


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint8, np.float32])
def test_integer_and_other_float_proposals_are_numbers(dtype):
    a_x, a_y = np.array([1, 0, 2], dtype), np.array([0, 1, 0], dtype)
    out_x, out_y, invalid = check_proposal("p", (a_x, a_y), 3, PRM)
    assert out_x.dtype == np.float64 and out_y.dtype == np.float64
    np.testing.assert_array_equal(out_x, [1.0, 0.0, 2.0])
    np.testing.assert_array_equal(out_y, [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(invalid, [False, False, False])


def test_a_list_pair_is_accepted_like_a_tuple():
    a = [np.array([0.5, -1.0]), np.array([0.1, 0.0])]
    out = check_proposal("p", a, 2, PRM)
    ref = check_proposal("p", tuple(a), 2, PRM)
    for got, want in zip(out, ref, strict=True):
        np.testing.assert_array_equal(got, want)


def _planner_function(obs, prm):  # a named planner
    return None


class _PlannerObject:
    def __call__(self, obs, prm):
        return None


@pytest.mark.parametrize(
    ("planner", "name"),
    [("my planner", "my planner"), (_planner_function, "_planner_function"), (_PlannerObject(), "_PlannerObject")],
)
def test_errors_name_the_planner(planner, name):
    ok = np.zeros(2)
    with pytest.raises(TypeError, match=f"nominal planner {name} must return a pair"):
        check_proposal(planner, (ok, ok, ok), 2, PRM)
    with pytest.raises(TypeError, match=f"nominal planner {name} must return a pair"):
        check_proposal(planner, np.zeros((2, 2)), 2, PRM)  # an array is not a pair
    with pytest.raises(TypeError, match=f"nominal planner {name} must return a pair"):
        check_proposal(planner, (ok,), 2, PRM)
    with pytest.raises(TypeError, match=f"nominal planner {name} returned a_y of dtype bool"):
        check_proposal(planner, (ok, np.zeros(2, bool)), 2, PRM)
    with pytest.raises(TypeError, match=f"nominal planner {name} returned a_x of dtype <U"):
        check_proposal(planner, (np.array(["a", "b"]), ok), 2, PRM)
    with pytest.raises(TypeError, match=f"nominal planner {name} returned a_x of dtype object"):
        check_proposal(planner, (None, ok), 2, PRM)
    with pytest.raises(TypeError, match=f"nominal planner {name} returned a_x of dtype complex"):
        check_proposal(planner, (ok + 0j, ok), 2, PRM)
    with pytest.raises(ValueError, match=rf"nominal planner {name} returned a_y of shape \(3,\); expected \(2,\)"):
        check_proposal(planner, (ok, np.zeros(3)), 2, PRM)
    with pytest.raises(ValueError, match=r"returned a_x of shape \(2, 1\); expected \(2,\)"):
        check_proposal(planner, (np.zeros((2, 1)), ok), 2, PRM)


def _decision(behaviour, invalid, flags=None):
    n = len(behaviour)
    flags = np.zeros((n, len(BREACH_KINDS)), bool) if flags is None else flags
    z = np.zeros(n)
    abort = (np.flatnonzero(np.asarray(behaviour) == ABORT), "knots", "px", "vx", "py", "vy")
    return Decision(
        behaviour=np.asarray(behaviour), a_x=z, a_y=z, completing=z.astype(bool), invalid=np.asarray(invalid),
        _plan=None, plan_t0=z, l1_decel=z, f_aggressive=z.astype(bool), breach=Breach(flags, np.full(n, np.nan)),
        nominal_x=z, nominal_y=z, _abort=abort,
    )  # fmt: skip


def test_intervened_is_hesitate_abort_or_an_invalid_proposal():
    behaviour = [PROCEED, HESITATE, ABORT, COMPLETED, PROCEED, HESITATE, ABORT, COMPLETED]
    invalid = [False] * 4 + [True] * 4
    d = _decision(behaviour, invalid)
    np.testing.assert_array_equal(d.intervened, [False, True, True, False, True, True, True, True])
    assert d.abort_motion() is d._abort and d.abort_motion()[1] == "knots"


def test_reasons_one_readable_sentence_per_row():
    flags = np.zeros((6, len(BREACH_KINDS)), bool)
    flags[5, 3] = True
    d = _decision([PROCEED, HESITATE, HESITATE, ABORT, COMPLETED, ABORT], [False, True, False, False, False, False],
                  flags)  # fmt: skip
    assert d.reasons() == [
        "proceed: the proposal keeps a safe evasion",
        "hesitate: invalid proposal",
        "hesitate: the proposal leaves no safe evasion",
        "abort: neither the proposal nor hesitating keeps a safe evasion; executing the held plan",
        "completed: following L1",
        "abort: neither the proposal nor hesitating keeps a safe evasion; executing the held plan"
        " (assumptions breached: most conservative worst case)",
    ]
    for kind in range(len(BREACH_KINDS)):  # any kind of breach is told
        flags = np.zeros((1, len(BREACH_KINDS)), bool)
        flags[0, kind] = True
        assert (
            _decision([PROCEED], [False], flags)
            .reasons()[0]
            .endswith("keeps a safe evasion (assumptions breached: most conservative worst case)")
        )


def test_the_tolerance_is_inclusive():
    """Exactly at a limit plus ``1e-9`` m/s² (the same float the rule computes) is still a valid proposal."""
    a_x = np.array([-PRM.a_x_d - 1e-9, PRM.a_x_a + 1e-9, 0.0, 0.0])
    a_y = np.array([0.0, 0.0, PRM.a_y_m + 1e-9, -(PRM.a_y_m + 1e-9)])
    out_x, out_y, invalid = check_proposal("p", (a_x, a_y), 4, PRM)
    assert not invalid.any()
    np.testing.assert_array_equal(out_x, a_x)
    np.testing.assert_array_equal(out_y, a_y)
