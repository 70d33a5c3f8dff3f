"""Two interchangeable element-wise backends for the safety math, and the mark of a row function.

The closed forms are written once against a tiny namespace ``xp`` (``where``, ``maximum``, ``minimum``,
``sqrt``, ``div``, ``stop_dist``). ``ARRAY`` maps it onto NumPy for batches; ``SCALAR`` maps it onto plain
Python floats, because a single check through NumPy pays ~1 µs of dispatch per operation. Both backends evaluate
both branches of ``where``, so every division goes through ``div`` (which never divides by zero) and every square
root clamps its argument at zero.

**One source, compiled.** ``SCALAR``'s operations are the module-level functions below, with NumPy's semantics
(``maximum``/``minimum`` propagate NaN as ``np.maximum``/``np.minimum`` do), so a closed form evaluated on
``SCALAR`` gives ``ARRAY``'s bits element by element. The same functions are numba's: :mod:`._compile` teaches numba
the type of ``SCALAR`` and compiles every function marked :func:`jitable` (the closed forms of ``lateral``,
``longitudinal``, ``chain``, ``evasion``) into the batch kernels, which are compiled loops over rows. There is no
second copy of a formula: uncompiled (``SAFELANE_NO_NUMBA=1``, mutation testing, debugging) the very same Python
functions run on NumPy arrays.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..tolerances import DIST_TOL_M

INF = math.inf

#: Gaps within this many metres of the margin count as satisfied (float round-off of the closed forms); the same
#: tolerance decides when a link's slack counts as exactly zero (``chain.min_follow_decel``).
FEASIBILITY_TOL_M = DIST_TOL_M

#: Every function marked :func:`jitable`, in the order they were marked: what :mod:`._compile` registers with numba.
ROW_FUNCTIONS: list = []


def jitable(*functions):
    """Mark backend-generic closed forms (and their helpers) as callable from compiled code.

    Changes nothing in Python and imports no numba: :mod:`._compile` registers every marked function with
    ``numba.extending.register_jitable`` before it compiles a kernel, so a kernel that calls one compiles its own
    source inline. A marked function may call only marked functions, ``xp``'s operations and ``math``; on ``SCALAR``
    it must be numba-typeable (no dicts, no ``is ARRAY`` tests, no NumPy calls). A call at the end of the module, not
    a decorator: mutmut leaves decorated functions unmutated, and these are the functions mutation testing is for.
    """
    ROW_FUNCTIONS.extend(functions)


def _where(cond, a, b):
    return a if cond else b


def _maximum(a, b):
    return a if (a >= b or a != a) else b  # NaN propagates (np.maximum)


def _minimum(a, b):
    return a if (a <= b or a != a) else b  # NaN propagates (np.minimum)


def _sqrt(x):
    return math.sqrt(_maximum(x, 0.0))  # a NaN stays NaN, as np.sqrt(np.maximum(x, 0))


def _clip(x, lo, hi):
    return _minimum(_maximum(x, lo), hi)


def _div(num, den, default):
    return num / den if den != 0.0 else default


def _stop_dist(v, a):
    """Braking distance ``v²/(2a)``; infinite when ``a = 0`` and ``v > 0``."""
    if a > 0.0:
        return v * v / (2.0 * a)
    return INF if v > 0.0 else 0.0


def _stop_time(v, a):
    """Time to stop ``v/a``; infinite when ``a = 0`` and ``v > 0``."""
    if a > 0.0:
        return v / a
    return INF if v > 0.0 else 0.0


# The operations of SCALAR, compiled into the kernels by _compile (numba) as they are.
jitable(_where, _maximum, _minimum, _sqrt, _clip, _div, _stop_dist, _stop_time)


class _Scalar:
    """Python-float implementation (inputs are ``float``/``bool``); numba's row backend (:mod:`._compile`)."""

    #: One row at a time: a closed form may skip a term that a ``where`` would discard there (``ARRAY``: ``False``,
    #: every element computes every term). The same bits either way; a kernel's row then skips the work.
    row = True

    where = staticmethod(_where)
    maximum = staticmethod(_maximum)
    minimum = staticmethod(_minimum)
    sqrt = staticmethod(_sqrt)
    clip = staticmethod(_clip)
    div = staticmethod(_div)
    stop_dist = staticmethod(_stop_dist)
    stop_time = staticmethod(_stop_time)


#: The operations of ``xp`` (each a static method of ``_Scalar`` and of ``_Array``).
OPERATIONS = ("where", "maximum", "minimum", "sqrt", "clip", "div", "stop_dist", "stop_time")


class _Array:
    """NumPy implementation (inputs are broadcastable float64/bool arrays)."""

    row = False

    where = staticmethod(np.where)
    maximum = staticmethod(np.maximum)
    minimum = staticmethod(np.minimum)

    @staticmethod
    def sqrt(x):
        return np.sqrt(np.maximum(x, 0.0))

    @staticmethod
    def clip(x, lo, hi):
        return np.minimum(np.maximum(x, lo), hi)

    @staticmethod
    def div(num, den, default):
        safe = np.where(den != 0.0, den, 1.0)
        return np.where(den != 0.0, num / safe, default)

    @staticmethod
    def stop_dist(v, a):
        safe = np.where(a > 0.0, a, 1.0)
        return np.where(a > 0.0, v * v / (2.0 * safe), np.where(v > 0.0, INF, 0.0))

    @staticmethod
    def stop_time(v, a):
        safe = np.where(a > 0.0, a, 1.0)
        return np.where(a > 0.0, v / safe, np.where(v > 0.0, INF, 0.0))


SCALAR = _Scalar()
ARRAY = _Array()


class Limits(NamedTuple):
    """The physical limits a closed form reads from :class:`~safelane.Params` (``prm.a_x_a`` …), as a record numba can
    take: the compiled kernels build one from the floats they are given; uncompiled code passes ``Params`` itself."""

    a_x_a: float
    a_x_d: float
    a_y_m: float
    y_safe: float

