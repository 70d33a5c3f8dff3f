"""The paper's traffic rules on hand-computed cases: an unexpected violation (paper §4.2) and the reactive leader.

Small batches (below ``behaviours.FAST_MIN_ELEMENTS``): the NumPy path, which evaluates the closed forms of
``sim/behaviours.py`` on arrays. Every expected number is worked out by hand below (exact in binary floating point),
so these tests judge the rules themselves, also where mutation testing mutates a compiled closed form and the
parity tests (``tests/test_fast_traffic.py``, marked ``compiled``) step aside.
"""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.sim.behaviours import leader_accels, leader_roles, reactive_leader_accels

PRM = Params()


def three_slots(x, v):
    """F, one connected leader L1 and L(N+1): positions and speeds ``(1, 3)``, margins of 2 m, the roles."""
    x, v = np.asfortranarray([x], dtype=float), np.asfortranarray([v], dtype=float)
    roles = leader_roles(np.ones((1, 3), bool), np.ones((1, 3), bool), np.array([1]))
    return x, v, np.full((1, 3), 2.0), roles


@pytest.mark.parametrize(
    ("pick", "decel_last", "expected"),
    [(0.0, 6.0, -2.0), (0.5, 6.0, -4.0), (1.0, 6.0, -6.0), (0.25, 1.0, -1.25)],
)
def test_an_unexpected_violation_brakes_uniformly_between_the_least_need_and_the_last_leaders_braking(
    pick, decel_last, expected
):
    # L1 at 10 m/s, 25 m clear of its margin behind L(N+1) at rest: it needs z = 10² / (2·25) = 2 m/s² (Eq. 3,
    # both stopped). The violation brakes at U[min(z, a_N+1), max(z, a_N+1)]: lo + pick·(hi − lo).
    x, v, margin, roles = three_slots([-20.0, 0.0, 27.0], [10.0, 10.0, 0.0])
    bounds = np.full((1, 3), PRM.a_x_d)
    task = np.zeros((1, 3))
    violating = np.array([[False, True, False]])
    pick_arr = np.array([[0.9, pick, 0.9]])
    acc = leader_accels(x, v, margin, roles, bounds, task, np.array([-3.0]), np.array([decel_last]), violating,
                        pick_arr, PRM)  # fmt: skip
    assert acc[0, 1] == expected
    assert acc[0, 2] == -3.0 and acc[0, 0] == 0.0  # L(N+1) on its profile, F untouched
    calm = leader_accels(x, v, margin, roles, bounds, task, np.array([-3.0]), np.array([decel_last]), None, None, PRM)
    assert calm[0, 1] == 0.0  # without the draw: its task (far enough behind a leader at rest to keep it)


@pytest.mark.parametrize(("task", "expected"), [(0.0, -4.0), (-5.0, -5.0), (1.0, -4.0)])
def test_the_reactive_leader_brakes_just_enough_for_the_vehicle_ahead_as_it_brakes_now(task, expected):
    # L1 and L(N+1) both at 12 m/s, 6 m clear of the margin; L(N+1) brakes at 6 m/s² now. Equal speeds, so the gap is
    # smallest once both stop: z = v² / (2·6 + v²/6) = 144 / (12 + 24) = 4 m/s². L1 takes min(task, −z).
    # F (slot 0) at rest, so a rule that read the wrong neighbour's speed would find another z.
    x, v, margin, roles = three_slots([-30.0, 0.0, 8.0], [0.0, 12.0, 12.0])
    tasks = np.array([[0.0, task, 0.0]])
    acc = reactive_leader_accels(x, v, margin, roles, tasks, np.array([-6.0]), np.array([6.0]), None, None, PRM)
    assert acc[0, 1] == expected and acc[0, 2] == -6.0 and acc[0, 0] == 0.0


def test_the_reactive_leaders_violation_uses_the_same_draw():
    # As above (z = 4) with an unexpected violation: U[min(4, 8), max(4, 8)] at pick 0.25 is 4 + 0.25·4 = 5.
    x, v, margin, roles = three_slots([-30.0, 0.0, 8.0], [0.0, 12.0, 12.0])
    violating = np.array([[False, True, False]])
    acc = reactive_leader_accels(x, v, margin, roles, np.zeros((1, 3)), np.array([-6.0]), np.array([8.0]),
                                 violating, np.array([[0.0, 0.25, 0.0]]), PRM)  # fmt: skip
    assert acc[0, 1] == -5.0
