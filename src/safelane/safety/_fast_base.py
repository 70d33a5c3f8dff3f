"""What every compiled kernel shares (numba; extra ``fast``): the scalar operations under their kernel names (the
backend's own functions, :mod:`._backend`, not copies), the row-function decorator, the array types of the kernels'
explicit signatures, the compile announcement and the on-disk cache's invalidation.

**The kernels' on-disk cache.** numba keys a cached kernel on the stamp of the file that defines it, but the helpers
a kernel calls from another file (these, :mod:`._fast_responsible`'s, the closed forms marked ``jitable``) are
compiled into it:
an edit there would leave the kernel's cached machine code stale. Every kernel module imports this one first, and
:func:`drop_stale_caches` runs once per process: when any kernel source changed since the stamp it keeps in
``__pycache__``, it deletes every kernel module's in-tree cache (``__pycache__/<module>.*.nbi|nbc``), so the next
call compiles afresh. (A ``NUMBA_CACHE_DIR`` cache is not cleared: there, clear it by hand after editing a kernel.)
"""

from __future__ import annotations

import functools
import hashlib
import math
import sys
from pathlib import Path

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import event
from numba.extending import intrinsic

from . import _backend, _compile
from .chain import braked_position

_compile.register_rows()

_INF = math.inf
_PACKAGE = Path(__file__).resolve().parents[1]


def _compiled_sources() -> tuple[Path, ...]:
    """Every module with a compiled kernel or its helpers: the ``_fast*.py`` modules, the backend and its numba
    registration, and every module with a closed form marked ``jitable`` (compiled into the kernels that call it)."""
    found = {_PACKAGE / "_motion.py", _PACKAGE / "_splitmix.py"}  # (compiled into the kernels)
    # (the expert's law, the envs' features and reward, RSS's rule)
    for sub in ("safety", "shield", "sim", "planners", "envs", "baselines"):
        for path in (_PACKAGE / sub).glob("*.py"):
            if path.name.startswith("_fast") or path.name in ("_backend.py", "_compile.py"):
                found.add(path)
            elif "\njitable(" in path.read_text(encoding="utf-8"):
                found.add(path)
    return tuple(sorted(found))


#: Every module whose source is compiled into a kernel (:func:`_compiled_sources`).
KERNEL_SOURCES = _compiled_sources()


def drop_stale_caches(sources=KERNEL_SOURCES, stamp: Path | None = None) -> bool:
    """Delete the in-tree numba caches of every module of ``sources`` when any of them changed since the last call
    (a SHA-256 of their bytes, kept in ``stamp``, by default beside this module's cache). Returns whether it
    deleted; never raises (a read-only install has nothing stale: its sources do not change)."""
    try:
        digest = hashlib.sha256(b"".join(p.read_bytes() for p in sources)).hexdigest()
        stamp = stamp or Path(__file__).resolve().parent / "__pycache__" / "safelane_kernels.sha256"
        if stamp.is_file() and stamp.read_text() == digest:
            return False
        for source in sources:
            for cached in (source.parent / "__pycache__").glob(f"{source.stem}.*.nb[ic]"):
                cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest)
        return True
    except OSError:
        return False


drop_stale_caches()

_ANNOUNCED: list[bool] = []


def say_compiling(stream=None) -> bool:
    """Say once per process (on stderr) that numba is compiling the kernels: a fresh install, or a kernel source
    edited. Measured on the 2-core development machine: a first run of the loop, the neural planner's compiled period
    and an env step with an empty cache took 53 s (``benchmarks/bench_cold_start.py``; 1.2 s once cached). Returns
    whether it spoke. Silent with ``NUMBA_DISABLE_JIT=1`` (nothing is compiled) and with ``NUMBA_CACHE_DIR`` (the
    cache is elsewhere: benchmarks and tests that time or isolate compilation)."""
    if _ANNOUNCED or numba.config.DISABLE_JIT or numba.config.CACHE_DIR:
        return False
    _ANNOUNCED.append(True)
    print("safelane: compiling the numba kernels on first use (about a minute, once; cached for later runs)",
          file=stream or sys.stderr, flush=True)  # fmt: skip
    return True


class _CompileListener(event.Listener):
    """numba's ``numba:compile`` event, which fires where a function of safelane is really compiled (a cache miss,
    not a load from the cache): the moment to say so (:func:`say_compiling`)."""

    def on_start(self, ev) -> None:
        dispatcher = (ev.data or {}).get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", None) or ""  # (None for some)
        if module.startswith("safelane."):
            say_compiling()

    def on_end(self, ev) -> None:
        pass


_LISTENING: list[bool] = []


def announce_compiles() -> None:
    """Listen, once per process, for the compilation of any of safelane's kernels and say so when it starts (each
    kernel module calls this at import). Before, a module announced at import when its folder held no cached kernel of
    it, which also spoke where nothing compiled (a module whose kernels a run never calls has no cache)."""
    if not _LISTENING:
        event.register("numba:compile", _CompileListener())
        _LISTENING.append(True)


def kernel(signature):
    """A batch kernel: ``numba.njit(signature, cache=True, nogil=True, error_model="numpy")``, compiled — or loaded from
    the cache — at its first call instead of at import. With the signature given, numba compiles at decoration:
    importing the part kernels' modules (which the compiled closed loop does, for their row functions) compiled or
    loaded all fourteen kernels, 9 s with an empty cache and 0.5 s from it, whether a run called them or not. The one
    specialization and its argument conversions are the signature's, as before (further compilation is disabled).
    Only Python calls a kernel; compiled code calls the row functions."""

    def wrap(fn):
        dispatcher = numba.njit(cache=True, nogil=True, error_model="numpy")(fn)

        @functools.wraps(fn)
        def call(*args):
            if not dispatcher.overloads:
                dispatcher.compile(signature)
                dispatcher.disable_compile()
            return dispatcher(*args)

        call.dispatcher = dispatcher
        return call

    return wrap


#: The decorator of the row functions the batch kernels and the compiled closed loop (``sim/_fast_loop.py``) share:
#: inlined by LLVM where called, and compiled without numba's reference counting (``_nrt=False``), so the arrays they
#: index cost no atomic increments per call (measured: a row function with array arguments ran the lane check 2.3x
#: slower than the same code written in the kernel; with these two options, as fast). Such a function may index
#: arrays and create views, never allocate.
row_function = numba.njit(error_model="numpy", nogil=True, _nrt=False, forceinline=True)



@intrinsic
def float_bits(typingctx, x):
    """The IEEE-754 bits of a float64 as a uint64 (NumPy's ``x.view(np.uint64)`` for one compiled value)."""
    if x != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.uint64(types.float64), codegen


@numba.njit(inline="always")
def sort_short(a):
    """``a.sort()`` of a short array in place, NaN last as NumPy sorts, allocating nothing (an insertion sort: code
    compiled without numba's reference counting — the row functions, the closed loop's rows — cannot call numba's
    quicksort, which may allocate)."""
    for i in range(1, a.shape[0]):
        key = a[i]
        j = i - 1
        while j >= 0 and (a[j] > key or (a[j] != a[j] and key == key)):
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = key


# One explicit signature (compiled at import, or loaded from the cache): read-only 1-D arrays of any layout, so
# contiguous inputs, broadcast scalars (stride 0) and read-only views all take the same machine code.
_F = types.Array(types.float64, 1, "A", readonly=True)
_B = types.Array(types.bool_, 1, "A", readonly=True)


# The scalar operations are the backend's own (``_backend``'s marked functions, registered with numba by
# ``_compile``): one definition of each, whether a closed form runs on NumPy arrays, on Python floats or compiled.
_max = _backend._maximum
_min = _backend._minimum
_sqrt = _backend._sqrt
_stop_time = _backend._stop_time
_stop_dist = _backend._stop_dist
_braked = braked_position  # called with the backend first: _braked(SCALAR, p, v, decel, t, t_stop)


def readonly(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a`` (what the signatures' read-only array types take; the caller's array is untouched)."""
    view = a.view()
    view.flags.writeable = False
    return view
