"""A shield over vehicles that come and go (:meth:`~.core.Shield.regroup`): the held state's rows selected and joined,
packed (the compiled path's arrays, :class:`~.fast_step.Packed`) or not (:class:`~.core.ShieldState`).

A new row has no previous period for the assumption monitor. Where the rows it joins have one, it gets a neutral
snapshot (:func:`neutral_snapshot`: ``active`` false, F unwatched, the chain far behind), so that its first period
flags nothing, as ``init``'s ``last = None`` does for a whole batch.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..params import Params
from .command import InFlight
from .monitor import Snapshot

_FAR_BEHIND_M = -1e9


def take_rows(obj, rows):
    """``obj`` (a frozen dataclass of ``(B, ...)`` arrays, nested) with the rows ``rows`` only; scalars and ``None``
    (and non-array members, e.g. parameters) stay as they are."""
    if obj is None or np.isscalar(obj) or isinstance(obj, str):
        return obj
    if isinstance(obj, np.ndarray):
        return obj[rows] if obj.ndim else obj
    if isinstance(obj, InFlight):  # (its commands index their aborting rows)
        return obj.take(rows)
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
    if isinstance(a, InFlight):
        return a.join(b)
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
