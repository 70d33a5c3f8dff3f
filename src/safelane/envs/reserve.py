"""The vector env's next episodes, prepared ahead in batches (:class:`Reserve`), for its resets on the compiled loop.

A reset used to build its finished rows' next episodes on the spot — draw the scenarios, a
:class:`~safelane.sim.step.ClosedLoop` over them, its initial state, the first observations, the compiled loop's inputs
(:class:`~safelane.sim._stepper.Stepper`) — a fixed cost of about 0.7 ms a reset, whether one row finished or a
hundred (measured: ``benchmarks/bench_env.py``'s random actions reset in most steps, a few rows each). The reserve
holds each sub-env's next ``depth`` episodes, prepared together for every sub-env whose stock ran out; a reset then
copies its rows' next episodes into the running batch (:meth:`~safelane.sim._stepper.Stepper.splice` with ``at``).

The scenarios are the same: sub-env ``i``'s generator is read by nothing but its own scenario draws, so drawing its
next episodes early, in their order, draws what it would have drawn at each reset (the episodes are prepared by the
same functions, from the same scenarios: ``tests/test_env_compiled.py`` compares every sub-env with a single env, bit
for bit).
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np
from numba import literal_unroll

from ..sim._stepper import Stepper
from ..sim.scenario import ScenarioBatch
from .rows import replace_rows

#: How many episodes ahead each sub-env is prepared: the reset of a sub-env whose stock ran out prepares every
#: sub-env's stock again (one batch), so a preparation covers many rows.
DEPTH = 2


class Reserve:
    """The next :data:`DEPTH` episodes of each of ``len(rngs)`` sub-envs of ``task``
    (:class:`~safelane.envs.core.LaneChangeTask`), sub-env ``i``'s drawn from ``rngs[i]``: episode ``j`` ahead of
    sub-env ``i`` lives in row ``i·depth + (head[i] + j) % depth`` of the prepared arrays (its compiled loop's
    inputs ``loop``, its state ``rows``, its first observation ``obs``, the env kernel's ``shares_plan`` and
    ``f_connected``, its scenario ``batch``); ``stock[i]`` of them are ready."""

    def __init__(self, task, rngs: Sequence[np.random.Generator], depth: int = DEPTH):
        self.task, self.rngs, self.depth = task, list(rngs), int(depth)
        n = len(self.rngs)
        self.stock, self.head = np.zeros(n, np.int64), np.zeros(n, np.int64)
        self.loop = self.rows = self.obs = self.shares_plan = self.f_connected = self.batch = None
        self.preparations = 0  # (how many batches were prepared)
        self.source = np.full(n, -1)  # the prepared row each sub-env's scenario is in, where not yet in task.batch
        self._pairs = None  # what restart copies: (the task's array, ours), made anew after a preparation

    def take(self, rows: np.ndarray) -> np.ndarray:
        """The prepared rows of sub-envs ``rows``' next episodes (taken: the next call gives the ones after),
        prepared first where a sub-env has none left."""
        if self.loop is None or not self.stock[rows].all():
            self._prepare()
        at = rows * self.depth + self.head[rows]
        self.head[rows] = (self.head[rows] + 1) % self.depth
        self.stock[rows] -= 1
        return at

    def _prepare(self) -> None:
        """Every sub-env's stock filled to ``depth`` episodes in one batch, each sub-env's drawn in its order."""
        d = self.depth
        missing = d - self.stock
        envs = np.repeat(np.arange(len(missing)), missing)
        later = np.arange(len(envs)) - np.repeat(np.cumsum(missing) - missing, missing)  # 0, 1, … within a sub-env
        at = envs * d + (self.head[envs] + self.stock[envs] + later) % d
        fresh = self.task.sampler.draw_many([self.rngs[i] for i in envs.tolist()])
        first, start, obs = self.task.first_states(fresh)
        part = Stepper(first)
        rows = part.state_of(start).rows
        if self.loop is None:  # (every row missing, none taken yet: ``at`` is 0, 1, 2, … in order)
            self.loop, self.obs, self.batch = part, obs, fresh
            self.rows = type(rows)(*[a.copy() for a in rows])  # (written in place from now on: ours)
            self.shares_plan, self.f_connected = np.array(first.shares_plan), np.array(first.b.connected[:, 0])
        else:
            self.task.batch  # noqa: B018  (the scenarios taken so far put in: self.batch is another one below)
            pairs = [*self.loop.splice_pairs(part), *zip(self.rows, rows, strict=True), (self.obs, obs),
                     (self.shares_plan, np.asarray(first.shares_plan)), (self.f_connected, first.b.connected[:, 0])]
            _copy_rows(_as_rows(pairs), at, np.arange(len(at)))
            self.batch = replace_rows(self.batch, fresh, at, len(self.obs))
        self.stock[:] = d
        self.preparations += 1
        self._pairs = None  # (our arrays may be others now: the first splice into the loop copies its inputs)

    def restart(self, rows: np.ndarray) -> np.ndarray:
        """Sub-envs ``rows`` of the task's compiled loop start their next episodes: their inputs, state and view
        replaced by the prepared ones; their first observations ``(len(rows), F)``."""
        task = self.task
        at = self.take(rows)
        if self._pairs is None:  # the loop's inputs as Stepper.splice copies them, the state, the env kernel's view
            pairs = [*task.loop.splice_pairs(self.loop), *zip(task.state.rows, self.rows, strict=True),
                     *zip(task._view[:2], (self.shares_plan, self.f_connected), strict=True)]  # fmt: skip
            self._pairs = _as_rows(pairs)
        _copy_rows(self._pairs, rows, at)
        self.source[rows] = at
        return self.obs[at]

    def scenarios(self, batch: ScenarioBatch) -> ScenarioBatch:
        """``batch``, the task's scenarios before the resets since the last call, with theirs put in (the task's
        :attr:`~safelane.envs.core.LaneChangeTask.batch`: nothing in a step reads it)."""
        rows = np.flatnonzero(self.source >= 0)
        if len(rows):
            batch = replace_rows(batch, self.batch.take(self.source[rows]), rows, len(self.source))
            self.source[:] = -1
        return batch


def _as_rows(pairs) -> tuple:
    """``(into, new)`` pairs as :func:`_copy_rows` takes them: the arrays that have columns, each as ``(rows,
    columns)`` — ``into`` a view (written through), ``new`` a view or a copy (only read)."""
    out = []
    for into, new in pairs:
        if into.size:
            rows = into.reshape(len(into), -1)
            if not np.may_share_memory(rows, into):
                raise ValueError("_as_rows: an array to write into has no (rows, columns) view")
            out.append((rows, new.reshape(len(new), -1)))
    return tuple(out)


@numba.njit(cache=True, nogil=True)
def _copy_rows(pairs, rows, at):
    """Row ``at[j]`` of each pair's second array into row ``rows[j]`` of its first, for every pair ``(into, new)`` of
    ``(rows, columns)`` arrays (:func:`_as_rows`), in one compiled call: NumPy's fancy indexing costs about a
    microsecond an array, and a reset copies some fifty; element by element, as no row is taken as a view (each view
    would count references)."""
    for pair in literal_unroll(pairs):
        into, new = pair
        for j in range(rows.shape[0]):
            r, a = rows[j], at[j]
            for c in range(into.shape[1]):
                into[r, c] = new[a, c]
