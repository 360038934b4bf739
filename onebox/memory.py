"""Keeping a long-running process's memory flat under a flood of large pictures.

glibc's malloc raises its mmap threshold each time a large block is freed (up to 32 MiB), so
after the first few pictures every 1.2 MB depth picture comes from a heap arena instead of its
own mapping; with Zenoh's callback threads each taking an arena of its own, the freed pictures
leave holes that are never given back, and the resident size climbs run after run. A fixed
threshold puts every picture in its own mapping, returned to the system when freed; two arenas
bound how many heaps can fragment; :func:`trim` gives back what the arenas hold free.

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
MMAP_THRESHOLD_BYTES = 128 * 1024
"""glibc's own starting value, kept fixed: a picture is far larger, a small message far smaller."""
ARENAS = 2


def _libc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux") or os.environ.get("ONEBOX_MALLOC") == "glibc":
        return None
    libc = ctypes.CDLL(None)
    return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None


def bound_heap() -> bool:
    """Fix malloc's mmap threshold and cap its arenas; call before threads start. True if set."""
    libc = _libc()
    if libc is None:
        return False
    ok = bool(libc.mallopt(M_ARENA_MAX, ARENAS) == 1)
    ok = bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1) and ok
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
