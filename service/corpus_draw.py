"""Corpus windows read by worker processes, with progress while they are drawn (issue 46).

``model fit`` reads the chain's evidence and the shapes of tens of thousands of simulated
windows (``simulator.corpus``). Each worker draws a chunk of up to ``CHUNK_WINDOWS`` windows
side by side, which takes minutes on a slow core, so progress told at the end of each chunk
came minutes apart (about 4 on the thirty-seventh session's 2 cores). The workers count every
window they read in one shared counter, and the caller hears of it every ``PROGRESS_EVERY_S``.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterator
from functools import partial
from multiprocessing.sharedctypes import Synchronized
from typing import TypeVar

from plantcheck.simulator.corpus import CorpusCase, read_chunk, window_chunks
from plantcheck.simulator.loop import LoopRecord

T = TypeVar("T")

PROGRESS_EVERY_S = 30.0
"""Seconds between two progress lines while windows are drawn."""

_read_count: Synchronized[int] | None = None
"""The pool's shared count of windows read, in each worker process (``_count_into``): a
multiprocessing value reaches a worker only through the pool's initializer."""


def _count_into(counter: Synchronized[int]) -> None:
    global _read_count
    _read_count = counter


def _one_read() -> None:
    if _read_count is not None:
        with _read_count.get_lock():
            _read_count.value += 1


def read_windows(
    read: Callable[[int, int, CorpusCase, LoopRecord], T],
    seed: int,
    first: int,
    n: int,
    jobs: int | None = None,
    progress: Callable[[str], None] | None = None,
    what: str = "windows",
    every_s: float = PROGRESS_EVERY_S,
) -> Iterator[T]:
    """``read(seed, index, case, record)`` of windows ``first``..n-1 of corpus ``seed``, in
    index order, read by ``jobs`` processes (default: one per core); ``progress`` hears the
    windows read of ``n``, the rate and the time left every ``every_s`` seconds and at the
    end. ``read`` must be a module-level function (it is sent to the workers)."""
    jobs = jobs or os.cpu_count() or 1
    ctx = multiprocessing.get_context("spawn" if sys.platform == "darwin" else "fork")
    counter: Synchronized[int] = ctx.Value("q", 0)
    t0 = last = time.monotonic()

    def tell() -> None:
        if progress is None:
            return
        done, took = counter.value, time.monotonic() - t0
        rate = done / max(took, 1e-9)
        left = f"about {(n - first - done) / rate:.0f} s left" if done else "starting"
        progress(f"corpus seed {seed}: {first + done}/{n} {what}, {rate:.0f}/s, {left}")

    with ctx.Pool(jobs, initializer=_count_into, initargs=(counter,)) as pool:
        chunks = pool.imap(
            partial(read_chunk, read, each=_one_read), window_chunks(seed, first, n, jobs)
        )
        while True:
            try:
                chunk = chunks.next(timeout=max(0.1, every_s - (time.monotonic() - last)))
            except multiprocessing.TimeoutError:
                chunk = None
            except StopIteration:
                break
            if time.monotonic() - last >= every_s:
                tell()
                last = time.monotonic()
            yield from chunk or ()
    tell()
