"""Allocator tuning for the batched engine (glibc only; opt out with ``SAFELANE_MALLOC_TUNING=0``).

A step of a 10,000-scenario batch makes hundreds of short-lived temporaries of up to a megabyte each. With
glibc's defaults the big ones are served by ``mmap`` until the dynamic threshold has grown, and the heap's top is
trimmed back to the OS and regrown over and over: every fresh mapping or regrowth page-faults, up to a quarter
of a run. Two ``mallopt`` settings remove both: temporaries up to 32 MiB (glibc's own ceiling for its dynamic
threshold) come from the heap, and 64 MiB of padding stays at its top. (Setting one alone is worse than none:
it switches the dynamic threshold off.) This changes no result, only speed; it is process-wide and permanent, so
it is applied once, on the first batched simulation, and can be disabled.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

_M_TOP_PAD, _M_MMAP_THRESHOLD = -2, -3  # glibc <malloc.h>
TOP_PAD_BYTES = 64 * 2**20
MMAP_THRESHOLD_BYTES = 32 * 2**20
_applied: bool | None = None


def tune_allocator() -> bool:
    """Apply the tuning once per process; True where glibc accepted it."""
    global _applied
    if _applied is None:
        _applied = _apply()
    return _applied


def _apply() -> bool:
    if os.environ.get("SAFELANE_MALLOC_TUNING", "1") == "0" or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        threshold = libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
        pad = libc.mallopt(_M_TOP_PAD, TOP_PAD_BYTES)
    except (OSError, AttributeError):  # no libc found, or one without mallopt (musl)
        return False
    return bool(threshold) and bool(pad)
