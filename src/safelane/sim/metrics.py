"""Rates with 95 % Wilson score intervals, and per-cell summaries of a results table."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pandas loads with the first table, not with the package
    import pandas as pd

Z95 = 1.959963984540054


def wilson_interval(successes, n, z: float = Z95):
    """Wilson score interval ``(lo, hi)`` for ``successes`` out of ``n`` (arrays broadcast; n > 0)."""
    successes = np.asarray(successes, dtype=float)
    n = np.asarray(n, dtype=float)
    if np.any(n <= 0):
        raise ValueError(f"n must be positive; got {n!r}")
    if np.any((successes < 0) | (successes > n)):
        raise ValueError("successes must lie in [0, n]")
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / denom
    half = z * np.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / denom
    # At k = 0 (k = n) the bound is exactly 0 (1); the formula leaves rounding residue such as 2.17e-19.
    lo = np.where(successes == 0, 0.0, np.clip(centre - half, 0.0, 1.0))
    hi = np.where(successes == n, 1.0, np.clip(centre + half, 0.0, 1.0))
    return lo, hi


RATE_COLUMNS = ("success", "collision", "safety_violation", "leader_collision")


def summarize(table: pd.DataFrame, by=("planner", "n_leaders", "decel", "p_v")) -> pd.DataFrame:
    """One row per cell: counts, rates and Wilson intervals of the outcome columns."""
    by = [c for c in by if c in table.columns]
    grouped = table.groupby(by, sort=False)
    out = grouped.size().rename("samples").to_frame()
    for col in RATE_COLUMNS:
        k = grouped[col].sum()
        lo, hi = wilson_interval(k.to_numpy(), out["samples"].to_numpy())
        out[f"{col}_rate"] = k / out["samples"]
        out[f"{col}_lo"] = lo
        out[f"{col}_hi"] = hi
    out["mean_completion_time_s"] = grouped["completion_time_s"].mean()
    return out.reset_index()
