"""Rolling windows kept in memory between a loop's diagnoses, so each run reads only new samples.

A loop diagnosed every 10 min on a 2-h window would otherwise re-read 12 times the samples it
needs. Per loop the cache holds each signal's (source timestamps µs, values) from the window
start on, plus the last value before it for the held signals (SP, mode: reported on change).
Each read fetches from ``lookback_s`` before the cached end, so samples that reach the store a
little late (the writer commits about once a second; a source may deliver in batches) replace
the cached tail; a full re-read every ``refresh_s`` picks up anything older written since (a
buffer replayed after a database outage). The cache is bounded (``max_bytes``, least recently
used loops dropped first): a loop that does not fit is read whole, as without a cache.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from plantcheck.storage.store import LoopRow, Store
from plantcheck.storage.window import LoopWindow, align

Series = dict[str, tuple[NDArray[np.int64], NDArray[np.float64]]]


@dataclass
class CachedWindow:
    """One loop's cached samples: per signal (timestamps µs, values), from ``start_us`` on,
    complete up to ``end_us``; ``before`` = last value before ``start_us`` of held signals."""

    start_us: int
    end_us: int
    series: Series
    before: dict[str, float]
    full_read_us: int
    """``end_us`` of the last full read (monotonic in source time)."""
    hold: tuple[str, ...] = field(default=())

    @property
    def nbytes(self) -> int:
        return sum(t.nbytes + v.nbytes for t, v in self.series.values())


def merge_tail(cached: Series, fresh: Series, from_us: int) -> Series:
    """``cached`` with every sample at or after ``from_us`` replaced by ``fresh`` (which
    holds the store's samples from ``from_us`` on)."""
    out: Series = {}
    for sig in cached.keys() | fresh.keys():
        t_old, v_old = cached.get(sig, (np.empty(0, np.int64), np.empty(0)))
        keep = int(np.searchsorted(t_old, from_us, side="left"))
        if sig in fresh:
            t_new, v_new = fresh[sig]
            out[sig] = (
                np.concatenate((t_old[:keep], t_new)),
                np.concatenate((v_old[:keep], v_new)),
            )
        else:
            out[sig] = (t_old[:keep], v_old[:keep])
    return out


def trim_head(
    series: Series, before: dict[str, float], start_us: int, hold: tuple[str, ...]
) -> tuple[Series, dict[str, float]]:
    """Drop samples before ``start_us``; a held signal's last dropped value becomes its
    ``before`` value (the value it holds when the window starts)."""
    out: Series = {}
    before = dict(before)
    for sig, (t, v) in series.items():
        k = int(np.searchsorted(t, start_us, side="left"))
        if k and sig in hold:
            before[sig] = float(v[k - 1])
        out[sig] = (t[k:], v[k:])
    return out, before


class WindowCache:
    """Per-loop rolling windows over a ``Store`` (one instance per scheduler)."""

    def __init__(
        self,
        store: Store,
        max_bytes: int = 256 << 20,
        lookback_s: float = 120.0,
        refresh_s: float = 3600.0,
    ) -> None:
        self.store = store
        self.max_bytes = max_bytes
        self.lookback_us = int(lookback_s * 1e6)
        self.refresh_us = int(refresh_s * 1e6)
        self._loops: OrderedDict[str, CachedWindow] = OrderedDict()
        self.nbytes = 0
        """Bytes held by the cached samples."""
        self.full_reads = 0
        self.tail_reads = 0

    def __len__(self) -> int:
        return len(self._loops)

    async def read_window(
        self, loop: LoopRow, start_us: int, end_us: int, hold: tuple[str, ...]
    ) -> LoopWindow:
        """The loop's window over [start, end), as ``Store.read_window`` returns it."""
        c = self._loops.pop(loop.name, None)
        if c is not None:
            self.nbytes -= c.nbytes
        usable = (
            c is not None
            and c.hold == hold
            and c.start_us <= start_us
            and start_us <= c.end_us <= end_us
            and end_us - c.full_read_us < self.refresh_us
        )
        if c is not None and usable:
            from_us = max(c.start_us, c.end_us - self.lookback_us)
            fresh = await self.store.read_series(loop, from_us, end_us)
            series, before = trim_head(
                merge_tail(c.series, fresh, from_us), c.before, start_us, hold
            )
            c = CachedWindow(start_us, end_us, series, before, c.full_read_us, hold)
            self.tail_reads += 1
        else:
            series = await self.store.read_series(loop, start_us, end_us)
            before = await self.store.last_before(loop, start_us, hold)
            c = CachedWindow(start_us, end_us, series, before, end_us, hold)
            self.full_reads += 1
        self._loops[loop.name] = c
        self.nbytes += c.nbytes
        while self._loops and self.nbytes > self.max_bytes:
            self.nbytes -= self._loops.popitem(last=False)[1].nbytes
        return align(c.series, start_us, end_us, None, c.before, hold)
