"""Handing freed memory back to the operating system between the phases of a run.

glibc's malloc raises its mmap threshold each time a large block is freed (up to 32 MiB), so
after the first few chunks most per-phase arrays of a big cloud come from the heap, and freed
heap pages stay resident: on a 1M-point run the peak resident memory grew by about 420 bytes
a point where the arrays alive at the peak take about 320 (docs/scaling.md, section Memory).
``malloc_trim(0)`` releases the free pages (also those between live blocks); it costs a few
milliseconds, so it is called at phase boundaries only. Elsewhere (no glibc) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _trim():
    """glibc's ``malloc_trim``, or None where the C library has none."""
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None


def release_freed_memory() -> None:
    """Return the heap's free pages to the operating system (no-op without glibc)."""
    trim = _trim()
    if trim is not None:
        trim(0)
