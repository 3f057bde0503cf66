"""Diagnosis workers that die with the service.

A ``ProcessPoolExecutor`` worker blocks on its call queue and outlives a service killed with
``kill -9`` (about 330 MB per crash, issue 27). Each worker watches its parent: when the parent
process id changes (the worker was re-parented to init or a subreaper), the service is gone
and the worker exits at once. Polling ``os.getppid`` is portable and, unlike Linux's
``PR_SET_PDEATHSIG``, does not fire when the thread that spawned the worker ends.
"""

from __future__ import annotations

import os
import threading
import time

from plantcheck.service.allocator import tune_allocator

PARENT_POLL_S = 0.5
"""How often a worker checks that the service still runs (s): the longest it outlives it."""


def _watch_parent(parent: int, poll_s: float) -> None:
    while True:
        if os.getppid() != parent:
            os._exit(0)  # nothing to flush: a worker only returns results to its parent
        time.sleep(poll_s)


def die_with_parent(parent: int, poll_s: float = PARENT_POLL_S) -> None:
    """Worker initializer: exit as soon as process ``parent`` (the service) is gone; keep
    the diagnosis's window-sized temporaries in the heap (``allocator``)."""
    tune_allocator()
    if os.getppid() != parent:
        os._exit(0)
    threading.Thread(
        target=_watch_parent, args=(parent, poll_s), name="parent-watch", daemon=True
    ).start()
