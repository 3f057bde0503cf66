"""Memory allocator settings for the processes that diagnose.

The chain works on window-sized numpy temporaries (a 3,600-sample window's lag grid is 200 kB,
a day's several MB). glibc's malloc serves blocks above its mmap threshold (128 kB at start,
raised only by the first such block freed) with fresh pages from the kernel, and returns heap
memory above its trim threshold at every free: each window then pays for the same page faults
again, 10 % of the standard chain's time (issue 29, measured with
``benchmarks/diagnosis_speed.py``). Fixed thresholds keep those blocks in the process's heap
between windows, for at most ``TRIM_BYTES`` of idle memory per process.

Only glibc has ``mallopt``; elsewhere this does nothing.
"""

from __future__ import annotations

import ctypes
import logging

log = logging.getLogger(__name__)

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
"""``mallopt`` parameters (glibc's malloc.h)."""

MMAP_BYTES = 16 * 2**20
"""Blocks up to this size come from the heap: every temporary of a day-long window at 1 s."""
TRIM_BYTES = 64 * 2**20
"""Free heap kept for the next window before it is returned to the system."""


def tune_allocator(mmap_bytes: int = MMAP_BYTES, trim_bytes: int = TRIM_BYTES) -> bool:
    """Set glibc's mmap and trim thresholds; True when they were set."""
    try:
        # the process's own symbols: libc is loaded already (find_library would run ldconfig)
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to tune
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    ok = bool(mallopt(M_MMAP_THRESHOLD, mmap_bytes)) and bool(mallopt(M_TRIM_THRESHOLD, trim_bytes))
    if not ok:
        log.debug("mallopt refused the thresholds")
    return ok
