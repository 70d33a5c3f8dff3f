"""Commands in flight select and join rows (``Command.take``, ``Command.join``, ``InFlight``; ``shield/rows.py``): a
row's command is the same command wherever the row goes — carrying the selected rows is selecting the carried ones."""

from __future__ import annotations

import numpy as np

from safelane.shield import rows as rws
from safelane.shield.command import Command, InFlight

DT = 0.1


def aborting_command(rng: np.random.Generator, n: int, aborting) -> Command:
    """A command for ``n`` rows whose rows ``aborting`` follow random knots over the period (some repeated)."""
    rows = np.asarray(aborting, np.intp)
    r = rows.size
    knots = np.sort(np.concatenate([np.zeros((r, 1)), rng.uniform(0.0, DT, (r, 6)), np.full((r, 1), DT)], 1), 1)
    knots[:, 3] = knots[:, 2]  # a zero-length segment
    vx, vy = rng.uniform(0.0, 30.0, (r, 8)), rng.normal(size=(r, 8))
    return Command.issued(rng.uniform(-6.0, 3.0, n), rng.normal(size=n), (rows, knots, None, vx, None, vy),
                          rng.random(n) < 0.3)  # fmt: skip


def ego(rng: np.random.Generator, n: int):
    return rng.uniform(-5.0, 5.0, n), rng.uniform(0.0, 3.5, n), rng.uniform(0.0, 30.0, n), rng.normal(size=n)


def test_take_and_join_keep_each_rows_command():
    rng = np.random.default_rng(4)
    a, b = aborting_command(rng, 9, [1, 4, 7]), aborting_command(rng, 5, [0, 3])
    idle = Command.idle(6)
    pick = np.array([7, 0, 4, 2], np.intp)
    start_a, start_b, start_i = ego(rng, 9), ego(rng, 5), ego(rng, 6)
    taken = a.take(pick)
    np.testing.assert_array_equal(taken.rows, [0, 2])  # rows 7 and 4 abort; 0 and 2 do not
    for got, want in zip(taken.carry(*(x[pick] for x in start_a), DT), a.carry(*start_a, DT), strict=True):
        np.testing.assert_array_equal(got, want[pick])
    joined = a.join(b).join(idle)
    np.testing.assert_array_equal(joined.rows, [1, 4, 7, 9, 12])
    starts = tuple(np.concatenate(parts) for parts in zip(start_a, start_b, start_i, strict=True))
    carried = [a.carry(*start_a, DT), b.carry(*start_b, DT), idle.carry(*start_i, DT)]
    for got, *want in zip(joined.carry(*starts, DT), *carried, strict=True):
        np.testing.assert_array_equal(got, np.concatenate(want))
    assert a.take(np.array([0, 2], np.intp)).knots is None  # no aborting row kept: one segment, as an idle command


def test_rows_of_a_state_select_and_join_its_commands_in_flight():
    rng = np.random.default_rng(8)
    queue = InFlight(commands=(aborting_command(rng, 6, [2]), aborting_command(rng, 6, [0, 5]), Command.idle(6)))
    other = InFlight.idle(3, 3)
    keep = np.array([5, 2, 1], np.intp)
    taken = rws.take_rows(queue, keep)
    assert [c.rows.tolist() for c in taken.commands] == [[1], [0], []]
    joined = rws.join_rows(taken, other)
    assert [len(c.a_x) for c in joined.commands] == [6, 6, 6]
    start = ego(rng, 6)
    for got, want in zip(taken.carry(*(x[keep] for x in start), DT), queue.carry(*start, DT), strict=True):
        np.testing.assert_array_equal(got, want[keep])
