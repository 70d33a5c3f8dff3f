"""Input validation and backend selection for the public safety functions.

Every public function names its inputs; a bad one raises ``ValueError`` saying which argument, which value,
where in the batch and what range was expected — never a NumPy error from deep inside the math.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np

from ..params import Params
from ._backend import ARRAY, SCALAR

_SCALAR_TYPES = (int, float, bool, np.floating, np.integer, np.bool_)


def check_params(params: object) -> None:
    """``params`` must be a :class:`safelane.Params` (a dict or anything else is a clear error)."""
    if not isinstance(params, Params):
        raise ValueError(f"params must be a safelane.Params; got {type(params).__name__}")


def _is_scalar(value: object) -> bool:
    return isinstance(value, _SCALAR_TYPES) or (isinstance(value, np.ndarray) and value.ndim == 0)


def _describe_bad(name: str, arr: np.ndarray, bad: np.ndarray, what: str) -> ValueError:
    idx = np.unravel_index(int(np.argmax(bad)), arr.shape) if arr.ndim else ()
    where = f" at index {tuple(int(i) for i in idx)}" if arr.ndim else ""
    value = arr[idx] if arr.ndim else arr[()]
    return ValueError(f"{name} must be {what}; got {value!r}{where}")


def float_array(name: str, raw: object) -> np.ndarray:
    """``raw`` as a float64 array; only real numbers (and booleans) are accepted — not strings, ``None``,
    complex numbers or ragged lists."""
    try:
        arr = np.asarray(raw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric array-like; got {raw!r}") from exc
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"{name} must be numeric array-like; got {raw!r}")
    return arr.astype(np.float64, copy=False)


_BOOL_WANTED = "a boolean (True/False or 0/1)"


def bool_array(name: str, raw: object) -> np.ndarray:
    """``raw`` as a bool array; booleans and the numbers 0 and 1 are accepted, anything else (NaN, 2, "yes") is
    an error rather than silently true."""
    try:
        arr = np.asarray(raw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be {_BOOL_WANTED} array-like; got {raw!r}") from exc
    if arr.dtype == np.bool_:
        return arr
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be {_BOOL_WANTED}; got {raw!r}")
    bad = (arr != 0) & (arr != 1)  # NaN is unequal to both
    if bad.any():
        raise _describe_bad(name, arr, bad, _BOOL_WANTED)
    return arr.astype(bool)


def _scalar_bool(name: str, raw: object) -> bool:
    if isinstance(raw, (bool, np.bool_)):
        return bool(raw)
    if raw == 0 or raw == 1:
        return bool(raw)
    raise ValueError(f"{name} must be {_BOOL_WANTED}; got {raw!r}")


def prepare(
    fields: Mapping[str, object],
    *,
    nonneg: Iterable[str] = (),
    bools: Iterable[str] = (),
    upper: Mapping[str, float] | None = None,
):
    """Validate named inputs and pick the backend.

    Returns ``(xp, values, shape)``: ``SCALAR`` with Python floats/bools when every input is a scalar,
    otherwise ``ARRAY`` with float64/bool arrays and their broadcast ``shape``.
    """
    nonneg = frozenset(nonneg)
    bools = frozenset(bools)
    upper = upper or {}
    if all(_is_scalar(v) for v in fields.values()):
        out: dict[str, object] = {}
        for name, raw in fields.items():
            if name in bools:
                out[name] = _scalar_bool(name, raw)
                continue
            value = float(raw)
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite; got {value!r}")
            if name in nonneg and value < 0.0:
                raise ValueError(f"{name} must be >= 0; got {value!r}")
            if name in upper and value > upper[name]:
                raise ValueError(f"{name} must be <= {upper[name]}; got {value!r}")
            out[name] = value
        return SCALAR, out, ()

    arrays: dict[str, np.ndarray] = {}
    for name, raw in fields.items():
        if name in bools:
            arrays[name] = bool_array(name, raw)
            continue
        arr = float_array(name, raw)
        finite = np.isfinite(arr)
        if not finite.all():
            raise _describe_bad(name, arr, ~finite, "finite")
        if name in nonneg and (arr < 0.0).any():
            raise _describe_bad(name, arr, arr < 0.0, ">= 0")
        if name in upper and (arr > upper[name]).any():
            raise _describe_bad(name, arr, arr > upper[name], f"<= {upper[name]}")
        arrays[name] = arr
    try:
        shape = np.broadcast_shapes(*(a.shape for a in arrays.values()))
    except ValueError as exc:
        shapes = ", ".join(f"{n}{a.shape}" for n, a in arrays.items())
        raise ValueError(f"input shapes do not broadcast together: {shapes}") from exc
    return ARRAY, arrays, shape


def finish(xp, shape, value, dtype=np.float64):
    """Return a backend result as a NumPy scalar (batch shape ``()``) or an array of the batch shape."""
    if xp is SCALAR:
        return dtype(value)
    arr = np.asarray(value, dtype=dtype)
    if arr.shape != shape:
        arr = np.broadcast_to(arr, shape).copy()
    return arr
