"""The one place equipped vehicles use the shield: :func:`decide`, one ``Shield.step`` per period over every
equipped vehicle that is changing lanes (a batch).

Rows come and go — a lane change starts, completes or is given up — while :class:`~safelane.shield.Shield` holds
one state for a fixed batch. :class:`ShieldPool` keeps that state aligned with the changers: each period it keeps
the rows of the changers that go on, initialises the rows of the new ones (``shield.init``: the plan held at the
start under the most conservative assumptions) and joins them, then calls ``Shield.step`` once. A new row has no
previous period for the assumption monitor: it gets a neutral snapshot (``active`` false, F unwatched, the chain far
behind), so its first period flags nothing, as ``init``'s ``last = None`` does for a whole batch.

Today's shield takes the paper's world (F, a leader chain, the own-lane leaders); a richer situation (several
lanes, other lane changers) changes what :func:`decide` is given, not its callers.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..params import Params
from ..shield import Shield, ShieldConfig, Situation
from ..shield.core import init
from ..shield.decision import Decision
from ..shield.monitor import Snapshot

_FAR_BEHIND_M = -1e9


def take_rows(obj, rows):
    """``obj`` (a frozen dataclass of ``(B, ...)`` arrays, nested) with the rows ``rows`` only; scalars and ``None``
    (and non-array members, e.g. parameters) stay as they are."""
    if obj is None or np.isscalar(obj) or isinstance(obj, str):
        return obj
    if isinstance(obj, np.ndarray):
        return obj[rows] if obj.ndim else obj
    if dataclasses.is_dataclass(obj):
        return dataclasses.replace(obj, **{f.name: take_rows(getattr(obj, f.name), rows)
                                           for f in dataclasses.fields(obj) if f.init})  # fmt: skip
    return obj  # parameters and other per-batch constants


def join_rows(a, b):
    """The rows of ``a`` then those of ``b`` (same structure; scalars from ``a``)."""
    if a is None or np.isscalar(a) or isinstance(a, str):
        return a
    if isinstance(a, np.ndarray):
        return np.concatenate([a, b]) if a.ndim else a
    if dataclasses.is_dataclass(a):
        return dataclasses.replace(a, **{f.name: join_rows(getattr(a, f.name), getattr(b, f.name))
                                         for f in dataclasses.fields(a) if f.init})  # fmt: skip
    return a


def neutral_snapshot(n: int, m: int, params: Params) -> Snapshot:
    """A monitor snapshot that flags nothing (rows without a previous period)."""
    return Snapshot(
        chain_x=np.full((n, m), _FAR_BEHIND_M), chain_v=np.zeros((n, m)), bounds=np.full((n, m), params.a_x_d),
        n_connected=np.zeros(n, np.int64), f_x=np.full(n, _FAR_BEHIND_M), f_v=np.zeros(n), f_limit=np.full(n, np.inf),
        plan_l1_decel=np.full(n, params.a_x_d), plan_f_aggr=np.ones(n, bool), active=np.zeros(n, bool),
    )  # fmt: skip


class ShieldPool:
    """One :class:`Shield` over a changing set of lane changes; ``calls`` counts its ``step`` calls."""

    def __init__(self, params: Params, variant: str = "CV_all", config: ShieldConfig | None = None):
        self.shield = Shield(params, variant=variant, config=config or ShieldConfig())
        self.params = params
        self.calls = 0

    def decide(self, situation: Situation, proposal, keep: np.ndarray, n_new: int) -> Decision:
        """``situation`` and ``proposal``: the rows of the changers that go on (``keep``: their rows in the last
        call's batch, in order) followed by ``n_new`` new ones."""
        sh = self.shield
        n_old = len(situation) - n_new
        if len(keep) != n_old:
            raise ValueError(f"keep has {len(keep)} rows; the situation has {n_old} continuing rows")
        keep = np.asarray(keep, np.int64)
        if n_new == 0 and 0 < n_old == sh.rows and (keep == np.arange(n_old)).all():
            # the same rows in the same order: the shield goes on from the state it holds (reading ``Shield.state``
            # would unpack the compiled path's arrays, and setting it would pack them again: most of a small step)
            self.calls += 1
            return sh.step(situation, proposal)
        if sh.state is None or n_old == 0:
            state = None
        elif n_old == len(sh.state.completed) and (keep == np.arange(n_old)).all():
            state = sh.state  # the same rows, new ones joining: nothing to select
        else:
            state = take_rows(sh.state, keep)
        if n_new:
            fresh = init(take_rows(situation, np.arange(n_old, len(situation))), self.params, sh.config, sh.variant)
            if state is not None and state.last is not None:
                fresh = dataclasses.replace(fresh, last=neutral_snapshot(n_new, situation.chain_x.shape[1],
                                                                         self.params))  # fmt: skip
            state = fresh if state is None else join_rows(state, fresh)
        sh.state = dataclasses.replace(state, t=situation.t)
        self.calls += 1
        return sh.step(situation, proposal)


def decide(pool: ShieldPool, situation: Situation, proposal, keep: np.ndarray, n_new: int) -> Decision:
    """The equipped vehicles' use of the shield (the one function): one batched decision for every changer."""
    return pool.decide(situation, proposal, keep, n_new)
