"""numba's view of the one source: the row backend's type and the registration of every :func:`~._backend.jitable`.

Importing this module imports numba and makes the closed forms marked :func:`~._backend.jitable` (``lateral``,
``longitudinal``, ``chain``, ``evasion``, … — the same Python functions that run on NumPy arrays) callable from
compiled code, evaluated on ``_backend.SCALAR``, whose operations are themselves marked functions. A kernel is then a
compiled loop over rows that calls the closed form once per row (``_fast.py``). numba compiles without ``fastmath``
(no fused multiply-add, no reassociation) and ``sqrt`` and ``/`` are correctly rounded, so a row gives the bits that
``ARRAY`` gives its element (``tests/test_fast_core.py``).

The backend object carries no data: numba sees it as an empty record (``RowBackend``) whose methods are the marked
operations, and lowers the global ``SCALAR`` as a constant, so a kernel writes ``evasion_core(SCALAR, ...)``.
"""

from __future__ import annotations

import inspect
import sys

from numba.core import cgutils, types
from numba.core.imputils import lower_constant
from numba.extending import (
    NativeValue,
    models,
    overload,
    overload_attribute,
    overload_method,
    register_model,
    typeof_impl,
    unbox,
)

from . import _backend, chain, evasion, lateral, longitudinal  # noqa: F401  (their closed forms are marked: registered below)


class RowBackend(types.Type):
    """numba's type of ``_backend.SCALAR``."""

    def __init__(self):
        super().__init__(name="safelane.RowBackend")


ROW_BACKEND = RowBackend()


@typeof_impl.register(_backend._Scalar)
def _typeof_scalar(value, context):
    return ROW_BACKEND


register_model(RowBackend)(lambda dmm, fe_type: models.StructModel(dmm, fe_type, []))


@unbox(RowBackend)
def _unbox_scalar(typ, obj, c):
    return NativeValue(cgutils.create_struct_proxy(typ)(c.context, c.builder)._getvalue())


@lower_constant(RowBackend)
def _constant_scalar(context, builder, typ, value):
    return cgutils.create_struct_proxy(typ)(context, builder)._getvalue()


def _method(fn):
    """``SCALAR.<name>(...)`` in compiled code calls the marked function ``fn`` (same parameters)."""
    params = ", ".join(inspect.signature(fn).parameters)
    namespace = {"fn": fn}
    exec(f"def overload(self, {params}):\n    return lambda self, {params}: fn({params})\n", namespace)
    return namespace["overload"]


_REGISTERED: set = set()


def source_of(fn):
    """The function numba compiles for the marked ``fn``: ``fn`` itself — or, while mutation testing has replaced it by
    mutmut's trampoline (which numba cannot compile), the unmutated original that mutmut keeps beside it
    (``x_<name>__mutmut_orig``). The kernels then stay the original code while the array path runs the mutant; where
    the mutant under test is in a marked function, ``tests/conftest.py`` skips the tests that compare the two (they
    would only restate that the mutant differs from the original)."""
    if "mutmut" not in fn.__code__.co_filename:
        return fn
    return getattr(sys.modules[fn.__module__], f"x_{fn.__name__}__mutmut_orig")


def _typer(implementation):
    def typer(*args, **kwargs):
        return implementation

    return typer


def register_rows() -> None:
    """Register every function marked so far with numba (idempotent). A kernel module imports the modules whose
    closed forms it compiles, then calls this before it defines a kernel (an explicit signature compiles at once).

    This is ``numba.extending.register_jitable`` with the implementation given by :func:`source_of`."""
    for fn in _backend.ROW_FUNCTIONS:
        if fn not in _REGISTERED:
            overload(fn, jit_options={}, inline="never", strict=False)(_typer(source_of(fn)))
            _REGISTERED.add(fn)


register_rows()
for _name in _backend.OPERATIONS:
    overload_method(RowBackend, _name)(_method(getattr(_backend._Scalar, _name)))


@overload_attribute(RowBackend, "row")
def _row(xp):
    """``SCALAR.row``: ``True``, a constant of the kernel (``_backend._Scalar.row``)."""
    return lambda xp: True
