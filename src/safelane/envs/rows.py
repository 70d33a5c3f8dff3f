"""Row surgery on the vector env's batched state: pad a batch's vehicle axis, stack single-row batches, replace or
vacate rows of any nested state (frozen dataclasses and tuples of arrays), shift a held plan's clock."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from ..sim.scenario import ScenarioBatch


def pad_vehicles(batch: ScenarioBatch, k: int) -> ScenarioBatch:
    """``batch`` with its vehicle axis padded to ``k`` slots the way :func:`safelane.sim.concat` pads (invalid,
    not connected, 1 km apart beyond the last vehicle)."""
    extra = k - batch.x.shape[1]
    if extra <= 0:
        return batch
    out = {}
    for f in dataclasses.fields(batch):
        a = getattr(batch, f.name)
        if isinstance(a, np.ndarray) and a.ndim == 2 and not f.name.startswith("last_profile"):
            pad = np.repeat(a[:, -1:], extra, axis=1)
            if f.name in ("valid", "connected", "human"):
                pad = np.zeros_like(pad)
            elif f.name == "x":
                pad = pad + 1e6 * np.arange(1, extra + 1)
            a = np.concatenate([a, pad], axis=1)
        out[f.name] = a
    return ScenarioBatch(**out)


def stack_rows(rows: Sequence[ScenarioBatch]) -> ScenarioBatch:
    """One batch from single-row batches of the same width."""
    return ScenarioBatch(
        **{
            f.name: None if getattr(rows[0], f.name) is None else np.concatenate([getattr(r, f.name) for r in rows])
            for f in dataclasses.fields(ScenarioBatch)
        }
    )


def replace_rows(tree, fresh, rows: np.ndarray, batch: int):
    """``tree`` (a state, a batch: nested frozen dataclasses and tuples of arrays) with ``rows`` of every array whose
    leading axis is the batch taken from ``fresh`` (the same structure over ``len(rows)`` rows); scalars (the clock)
    stay ``tree``'s. Arrays keep their memory layout (the engine keeps per-vehicle arrays column-major)."""
    if isinstance(tree, np.ndarray):
        if tree.ndim == 0 or tree.shape[0] != batch:
            return tree
        out = tree.copy(order="K")
        out[rows] = fresh
        return out
    if isinstance(tree, tuple):
        return _like(tree, [replace_rows(a, b, rows, batch) for a, b in zip(tree, fresh, strict=True)])
    if dataclasses.is_dataclass(tree) and not isinstance(tree, type):
        changes = {}
        for f in dataclasses.fields(tree):
            old, new = getattr(tree, f.name), getattr(fresh, f.name)
            if new is None and dataclasses.is_dataclass(old):
                changes[f.name] = vacate_rows(old, rows, batch)
            elif isinstance(old, np.ndarray | tuple) or dataclasses.is_dataclass(old):
                changes[f.name] = replace_rows(old, new, rows, batch)
        return dataclasses.replace(tree, **changes)
    return tree


def vacate_rows(record, rows: np.ndarray, batch: int):
    """``record`` with ``rows`` emptied where a fresh state has no record at all (``None``: the shield's memory of
    the previous period before the first one): flags ``False``, counts ``-1``, values NaN — every comparison with
    an emptied row is false, so nothing is inferred from it."""
    if isinstance(record, np.ndarray):
        if record.ndim == 0 or record.shape[0] != batch:
            return record
        out = record.copy(order="K")
        out[rows] = False if out.dtype == bool else (-1 if out.dtype.kind in "iu" else np.nan)
        return out
    if isinstance(record, tuple):
        return _like(record, [vacate_rows(a, rows, batch) for a in record])
    if dataclasses.is_dataclass(record) and not isinstance(record, type):
        return dataclasses.replace(
            record, **{f.name: vacate_rows(getattr(record, f.name), rows, batch) for f in dataclasses.fields(record)}
        )
    return record


def shift_plan_clock(tree, t: float):
    """``tree`` (a fresh initial state) with the time origin of its held plans (every field ``plan_t0``, wherever
    the state keeps it) moved from 0 to the batch time ``t``."""
    if not dataclasses.is_dataclass(tree) or isinstance(tree, type):
        return tree
    changes = {}
    for f in dataclasses.fields(tree):
        value = getattr(tree, f.name)
        if f.name == "plan_t0":
            changes[f.name] = value + t
        elif dataclasses.is_dataclass(value):
            changes[f.name] = shift_plan_clock(value, t)
    return dataclasses.replace(tree, **changes)


def _like(tree: tuple, items: list) -> tuple:
    """``items`` as a tuple of ``tree``'s type (a named tuple stays one)."""
    return type(tree)(*items) if hasattr(tree, "_fields") else tuple(items)
