"""glibc's allocator tuned for column-sized temporaries: a setting of the whole process.

Scoring makes and frees many arrays the size of a column; glibc hands blocks above 128 KiB back
to the system at once, so each was page-faulted in afresh. :func:`tune_allocator` keeps them in
the heap. It is process-wide and runs once, when the first :class:`DataCache` is made (before any
data are read), so memory figures measured after that point are those of a tuned heap.
"""

from __future__ import annotations

import os
import sys
import threading

__all__ = ["ALLOCATOR_KEEP_BYTES", "tune_allocator"]

#: glibc returns freed blocks above 128 KiB to the system at once, so every column-sized
#: temporary (2.9 MB for an hour at 100 Hz) was page-faulted in afresh: 9 of 17 CPU seconds
#: of the 600-signal hour were the kernel's. Blocks up to this size stay in the heap, and the
#: heap keeps this much free memory for the next one (docs/performance.md, "Allocator").
ALLOCATOR_KEEP_BYTES = 1 << 27


_allocator_tuned = threading.Event()


def tune_allocator() -> None:
    """Keep column-sized blocks in glibc's heap (once per process; Linux only, and never
    against a MALLOC_MMAP_THRESHOLD_ or MALLOC_TRIM_THRESHOLD_ the user set)."""
    if _allocator_tuned.is_set():
        return
    _allocator_tuned.set()
    if not sys.platform.startswith("linux"):
        return
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "MALLOC_TRIM_THRESHOLD_" in os.environ:
        return
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:  # musl or another C library: leave it as it is
        return
    m_trim_threshold, m_mmap_threshold = -1, -3
    libc.mallopt(m_mmap_threshold, ALLOCATOR_KEEP_BYTES)
    libc.mallopt(m_trim_threshold, 2 * ALLOCATOR_KEEP_BYTES)
