"""Malloc for a long-running process that handles a stream of large pictures.

A picture's arrays are a few MB each. glibc's malloc maps each block that large afresh and
unmaps it when freed, so every picture's pages are faulted in again (on a 640 x 480 stereo or
YCB-Video capture, a quarter of the box finder's time); and left to itself it raises its mmap
threshold as large blocks are freed while Zenoh's callback threads each take an arena of their
own, so the freed pictures leave holes across many heaps and the resident size climbs.
:func:`bound_heap` fixes the threshold at glibc's largest (blocks up to 32 MiB come from the
heap, where the next picture reuses them) and keeps up to 256 MiB free on the heap rather than
give it back at every free; two arenas bound how many heaps can fragment; :func:`trim` gives
back what the arenas hold free, once an interval.

``ONEBOX_MALLOC=glibc`` leaves glibc's defaults, to measure the difference
(``benchmarks/bench_faults.py`` does).
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys

log = logging.getLogger("memory")

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
M_ARENA_MAX = -8
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
"""glibc's largest: a picture's blocks come from the heap and are reused, not mapped afresh."""
TRIM_THRESHOLD_BYTES = 256 * 1024 * 1024
"""Free memory the heap keeps for the next picture between :func:`trim` calls."""
ARENAS = 2


def _libc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux") or os.environ.get("ONEBOX_MALLOC") == "glibc":
        return None
    libc = ctypes.CDLL(None)
    return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None


def bound_heap() -> bool:
    """Fix malloc's mmap and trim thresholds and cap its arenas; call before threads start.
    True if set."""
    libc = _libc()
    if libc is None:
        return False
    ok = bool(libc.mallopt(M_ARENA_MAX, ARENAS) == 1)
    ok = bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1) and ok
    ok = bool(libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1) and ok
    if not ok:
        log.info("malloc kept its defaults (mallopt refused)")
    return ok


def trim() -> None:
    """Give the free memory at the top of malloc's heaps back to the system."""
    libc = _libc()
    if libc is not None:
        libc.malloc_trim(0)


def rss_mb(pid: int | str = "self") -> float:
    """Resident size of a process in MB, from /proc (0 where there is no /proc)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        return 0.0
    return 0.0
