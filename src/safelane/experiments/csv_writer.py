"""``write_csv(frame, path)``: the bytes of ``frame.to_csv(path, index=False)``, written about three times as fast.

pandas formats a float column with NumPy's ``astype(str)`` and hands every cell to the ``csv`` module; the run's
scenario tables (358,004 rows of 33–36 columns) spend seconds there. Here each column becomes a list of strings
once — a float by ``float.__repr__`` (the shortest round-trip digits, as NumPy's ``str``), ``NaN`` as the empty
string, a boolean as ``True``/``False``, an integer by ``str``; a number once per distinct value where values repeat
(``decel``, ``p_v``, the completion times, the counts) — and the rows are joined with commas.

Only what this path reproduces exactly takes it: a frame with a default index, at least two columns, columns of
NumPy bool, integer or float64 dtype or of strings, and no name or string that the ``csv`` module would quote
(a comma, a quote, a line break or a leading space). Anything else is written by pandas itself, so the bytes are
pandas' in every case (``tests/test_csv_writer.py`` compares them on every dtype and edge value).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

_BOOL = np.array(["False", "True"], dtype=object)
_QUOTED = (",", '"', "\r", "\n")
#: A float column is formatted through its distinct values when it has at most this share of distinct values.
_DISTINCT_SHARE = 0.5


def write_csv(frame: pd.DataFrame, path: str | Path) -> None:
    """Write ``frame`` as ``frame.to_csv(path, index=False)`` writes it, byte for byte."""
    text = csv_text(frame)
    if text is None:
        frame.to_csv(path, index=False)
        return
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(text)


def csv_text(frame: pd.DataFrame) -> str | None:
    """The text of ``frame.to_csv(index=False)``, or ``None`` where this fast path does not reproduce pandas."""
    if frame.shape[1] < 2 or not isinstance(frame.index, pd.RangeIndex) or frame.columns.nlevels != 1:
        return None
    names = list(frame.columns)
    if not all(isinstance(n, str) and _plain(n) for n in names):
        return None
    columns = []
    for k in range(frame.shape[1]):
        cells = _cells(frame.iloc[:, k])
        if cells is None:
            return None
        columns.append(cells)
    sep = os.linesep
    return sep.join([",".join(names), *map(",".join, zip(*columns, strict=True))]) + sep


def _plain(text: str) -> bool:
    return not any(c in text for c in _QUOTED) and not text.startswith(" ")


def _cells(column: pd.Series) -> list[str] | None:
    """Every cell of ``column`` as pandas writes it, or ``None`` for a dtype this path does not handle."""
    dtype = column.dtype
    if isinstance(dtype, np.dtype):
        values = column.to_numpy()
        if dtype.kind == "b":
            return _BOOL[values.view(np.uint8)].tolist()
        if dtype.kind in "iu":
            return _int_cells(values)
        if dtype == np.float64:
            return _float_cells(values)
        if dtype.kind != "O":
            return None
    elif not isinstance(dtype, pd.StringDtype):
        return None
    cells = column.to_numpy(dtype=object, na_value="").tolist()
    try:
        distinct = set(cells)  # a few names, checked once each
    except TypeError:  # unhashable objects
        return None
    if not all(isinstance(c, str) and _plain(c) for c in distinct):
        return None
    return cells


def _int_cells(values: np.ndarray) -> list[str]:
    """``str`` of each integer, once per distinct value when values repeat (counts, cells, N)."""
    distinct, inverse = np.unique(values, return_inverse=True)
    if len(distinct) > _DISTINCT_SHARE * len(values):
        return list(map(str, values.tolist()))
    return np.array(list(map(str, distinct.tolist())), dtype=object)[inverse].tolist()


def _float_cells(values: np.ndarray) -> list[str]:
    """``repr`` of each float (``NaN`` empty), formatted once per distinct bit pattern when values repeat (the bit
    pattern, not the value: ``-0.0`` and ``0.0`` are written differently)."""
    bits = values.view(np.int64)
    distinct, inverse = np.unique(bits, return_inverse=True)
    if len(distinct) > _DISTINCT_SHARE * len(values):
        cells = list(map(float.__repr__, values.tolist()))
        for i in np.flatnonzero(np.isnan(values)).tolist():
            cells[i] = ""
        return cells
    uniques = distinct.view(np.float64)
    texts = np.array(["" if u != u else repr(u) for u in uniques.tolist()], dtype=object)  # u != u: NaN
    return texts[inverse].tolist()
