"""The allocator told to keep the memory NumPy frees, for the filter's large temporaries.

A filter iteration makes arrays of the whole particle set again and again (the Liu-West
draw, the packed dimensions, the settle's copies: 57 MB each at 600,000 particles). glibc's
malloc serves an allocation above its mmap threshold (128 kB, rising to at most 32 MB as
such blocks are freed) with fresh pages from the kernel and returns them when freed, so
each such array pays a page fault per 4 kB on first touch: measured at 600,000 particles,
the jitter phase 5.7 s against 4.0 s and the Liu-West draw alone 1.31 s against 0.16 s
with the memory kept (docs/DECISIONS.md). `keep_freed_memory` raises the threshold to
1 GiB and stops the heap's trimming (`mallopt`, M_MMAP_THRESHOLD and M_TRIM_THRESHOLD), so
that freed arrays are reused; the process keeps its peak memory until it exits. Elsewhere
than glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

log = logging.getLogger(__name__)

# mallopt's parameters (malloc.h).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 1 << 30
TRIM_THRESHOLD = 2**31 - 1

_applied: bool | None = None


def keep_freed_memory() -> bool:
    """Tell glibc's malloc to keep freed memory for reuse (module docstring), once per
    process; whether it took."""
    global _applied
    if _applied is None:
        _applied = False
        name = ctypes.util.find_library("c")
        try:
            libc = ctypes.CDLL(name) if name else None
            mallopt = getattr(libc, "mallopt", None)
        except OSError:
            mallopt = None
        if mallopt is not None:
            _applied = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
                            and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
        log.debug("malloc keeps freed memory: %s", _applied)
    return _applied
