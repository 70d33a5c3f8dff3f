"""Words chosen by the numbers: the report's sentences are assembled from these, so none can say "more" where its
table shows less, "without" where it shows a violation, or print a sign its wording contradicts.

Every helper takes the numbers and returns text; nothing here knows a result. "Clearly" means the 95 % Wilson
intervals do not overlap, as in :mod:`safelane.experiments.claims`.
"""

from __future__ import annotations

import math

import pandas as pd


def clearly(a: tuple[float, float], b: tuple[float, float]) -> int:
    """+1 when interval ``a = (lo, hi)`` lies wholly above ``b``, -1 wholly below, 0 when they overlap."""
    if a[0] > b[1]:
        return 1
    if a[1] < b[0]:
        return -1
    return 0


def more_or_fewer(diff: float, clear: int | None = None, *, more: str = "more", fewer: str = "fewer",
                  same: str = "as many") -> str:  # fmt: skip
    """The comparison word for ``diff = a - b``; with ``clear`` (see :func:`clearly`) an overlap says ``same``."""
    if clear == 0 or diff == 0 or math.isnan(diff):
        return same
    return more if diff > 0 else fewer


def points(diff: float, word: str) -> str:
    """``"2.9 percentage points fewer"``: the magnitude of a rate difference with its word (never a sign that
    contradicts the word)."""
    return f"{abs(100 * diff):.1f} percentage points {word}"


def count(k: float) -> int:
    return round(float(k))


def share(rate: float, samples: int | None = None, *, noun: str = "") -> str:
    """A rate as a percentage that never rounds a non-zero rate to "0.0 %": ``none``, ``0.02 % (1 of 4500)`` or
    ``74.2 %``."""
    noun = f" {noun}" if noun else ""
    if math.isnan(rate):
        return "—"
    k = None if samples is None else count(rate * samples)
    if rate == 0 or k == 0:
        return f"no{noun}" if noun else "0 %"
    if rate < 0.001 or (k is not None and k < 10):
        text = f"{100 * rate:.2g} %"
        return f"{text}{noun} ({k} of {samples})" if k is not None else f"{text}{noun}"
    return f"{100 * rate:.1f} %{noun}"


def with_or_without(rate: float, samples: int | None, noun: str) -> str:
    """``"without a collision"`` or ``"with 0.02 % collisions (1 of 4500)"``."""
    if rate == 0 or (samples is not None and count(rate * samples) == 0):
        return f"without a {noun}"
    return f"with {share(rate, samples)} {noun}s"


def plural(k: int, noun: str) -> str:
    return f"{k} {noun}" + ("" if k == 1 else "s")


def closer(a: float, b: float, target: str, other: str) -> str:
    """``a`` and ``b`` are distances to ``target`` (e.g. mean absolute differences, compared as printed, to 3
    decimals): ``"closer to the paper than the rule-based planner"`` and the like."""
    if round(a, 3) == round(b, 3):
        return f"as close to {target} as {other}"
    return f"{'closer to' if a < b else 'further from'} {target} than {other}"


def join(items: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    items = list(items)
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def number(x, fmt: str = ".3f") -> str:
    """``x`` formatted (``—`` for a missing value)."""
    return "—" if x is None or pd.isna(x) else format(float(x), fmt)
