"""Busy processes beside a benchmark (``--cpu-load N``): a loaded CI machine, where timings
that an idle machine meets with room to spare may not be met (takeover.py, disk_faults.py)."""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Iterator
from contextlib import contextmanager


def _spin() -> None:
    while True:
        pass


@contextmanager
def busy_processes(n: int) -> Iterator[None]:
    """``n`` processes each keeping a core busy while the block runs, killed when it ends."""
    spinners = [mp.Process(target=_spin, daemon=True) for _ in range(n)]
    for s in spinners:
        s.start()
    try:
        yield
    finally:
        for s in spinners:
            s.kill()
