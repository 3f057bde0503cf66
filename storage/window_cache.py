"""Rolling windows kept in memory between a loop's diagnoses, so each run reads only new samples.

A loop diagnosed every 10 min on a 2-h window would otherwise re-read 12 times the samples it
needs. Per loop the cache holds each signal's (source timestamps µs, values) from the window
start on, plus the last value before it for the held signals (SP, mode: reported on change).
Each read fetches from ``lookback_s`` before the cached end, so samples that reach the store a
little late (the writer commits about once a second; a source may deliver in batches) replace
the cached tail. Every ``refresh_s`` the cached part before the look-back is checked against
the store: the samples per signal are counted (no values read), and when a count differs
(samples written later than the look-back: a buffer replayed after a database outage, an
import) the window is read whole again. Stored samples are never changed in place (writes are
idempotent inserts), so equal counts mean equal samples. The cache is bounded (``max_bytes``,
least recently used loops dropped first): a loop that does not fit is read whole, as without
a cache.

``read_latest`` gives the window that ends at the loop's newest stored PV sample (source time):
the tail read is open-ended, so the newest sample comes with it and the oldest is remembered
from the last full read; only a full read asks the store for the PV span.
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
    """``end_us`` of the last full read or check against the store (monotonic in source
    time)."""
    hold: tuple[str, ...] = field(default=())
    oldest_pv_us: int | None = None
    """Oldest stored PV sample at the last full read (None: not known)."""

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


@dataclass(frozen=True)
class LatestWindow:
    """The window ``read_latest`` chose and read, with notes on how it was chosen."""

    window: LoopWindow
    start_us: int
    end_us: int
    notes: list[str]
    filling: bool
    """Shorter than the configured window: all the data stored so far (a service just
    started, a loop just added), so the next read holds more."""


def window_bounds(
    pv_span: tuple[int, int] | None, now_us: int, window_us: int
) -> tuple[int, int, list[str], bool]:
    """(start µs, end µs, notes, filling) of a loop's window of ``window_us`` given its oldest
    and newest stored PV sample: ending just after the newest (the plant's own time base),
    shortened to the data stored so far (``filling``); ending now when the newest is older than
    a window (the chain then reports the missing data)."""
    if pv_span is None or pv_span[1] < now_us - window_us:
        return (
            now_us - window_us,
            now_us,
            [
                "no PV sample stored in the last window: check the source and its connection"
                if pv_span is not None
                else "no PV sample stored yet"
            ],
            False,
        )
    end_us = pv_span[1] + 1
    start_us = max(end_us - window_us, pv_span[0])
    filling = start_us > end_us - window_us
    notes = []
    if filling:
        notes.append(
            f"window shortened to the {(end_us - start_us) / 1e6:.0f} s of data stored so far "
            f"(configured {window_us / 1e6:g} s)"
        )
    return start_us, end_us, notes, filling


OPEN_END_US = 1 << 62
"""An end later than any timestamp (µs): an open-ended read."""


class WindowCache:
    """Per-loop rolling windows over a ``Store`` (one instance per scheduler)."""

    def __init__(
        self,
        store: Store,
        max_bytes: int = 256 << 20,
        lookback_s: float = 30.0,
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
        self.checks = 0
        """Refresh checks that found the cached samples complete (no full read needed)."""

    def __len__(self) -> int:
        return len(self._loops)

    async def read_latest(
        self, loop: LoopRow, window_us: int, hold: tuple[str, ...], now_us: int
    ) -> LatestWindow:
        """The loop's window of ``window_us`` ending at its newest stored PV sample (see
        ``window_bounds``), read from the cache and the samples stored since."""
        c = self._take(loop, hold)
        if c is not None and c.oldest_pv_us is not None:
            from_us = max(c.start_us, c.end_us - self.lookback_us)
            fresh = await self.store.read_series(loop, from_us, OPEN_END_US, kept=True)
            pv_t = fresh.get("pv", c.series.get("pv", (np.empty(0, np.int64), None)))[0]
            if pv_t.size:
                start_us, end_us, notes, filling = window_bounds(
                    (c.oldest_pv_us, int(pv_t[-1])), now_us, window_us
                )
                if self._usable(c, start_us, end_us) and await self._complete(
                    loop, c, from_us, end_us
                ):
                    fresh = {sig: _before(t, v, end_us) for sig, (t, v) in fresh.items()}
                    return LatestWindow(
                        self._extend(loop, c, fresh, from_us, start_us, end_us),
                        start_us,
                        end_us,
                        notes,
                        filling,
                    )
        span = await self.store.sample_span_us(loop, "pv", kept=True)
        start_us, end_us, notes, filling = window_bounds(span, now_us, window_us)
        oldest = None if span is None else span[0]
        win = await self._read_whole(loop, start_us, end_us, hold, oldest)
        return LatestWindow(win, start_us, end_us, notes, filling)

    def _take(self, loop: LoopRow, hold: tuple[str, ...]) -> CachedWindow | None:
        """The loop's cached window (removed from the cache until put back), if it was read
        with the same held signals."""
        c = self._loops.pop(loop.name, None)
        if c is not None:
            self.nbytes -= c.nbytes
        return c if c is not None and c.hold == hold else None

    def _usable(self, c: CachedWindow, start_us: int, end_us: int) -> bool:
        """Whether ``c`` plus a tail read can give the window [start, end): it moved forward."""
        return c.start_us <= start_us and start_us <= c.end_us <= end_us

    async def _complete(self, loop: LoopRow, c: CachedWindow, from_us: int, end_us: int) -> bool:
        """Whether ``c`` still holds every stored sample before ``from_us``: assumed until a
        refresh is due, then checked by counting the stored samples per signal."""
        if end_us - c.full_read_us < self.refresh_us:
            return True
        cached = {sig: int(np.searchsorted(t, from_us)) for sig, (t, _) in c.series.items()}
        stored = await self.store.count_series(loop, c.start_us, from_us, kept=True)
        if stored != {sig: n for sig, n in cached.items() if n}:
            return False
        c.full_read_us = end_us
        self.checks += 1
        return True

    def _extend(
        self,
        loop: LoopRow,
        c: CachedWindow,
        fresh: Series,
        from_us: int,
        start_us: int,
        end_us: int,
    ) -> LoopWindow:
        """``c`` with its tail from ``from_us`` replaced by ``fresh``, cut to [start, end)."""
        series, before = trim_head(merge_tail(c.series, fresh, from_us), c.before, start_us, c.hold)
        self.tail_reads += 1
        return self._keep(
            loop,
            CachedWindow(start_us, end_us, series, before, c.full_read_us, c.hold, c.oldest_pv_us),
        )

    async def _read_whole(
        self,
        loop: LoopRow,
        start_us: int,
        end_us: int,
        hold: tuple[str, ...],
        oldest_pv_us: int | None,
    ) -> LoopWindow:
        series = await self.store.read_series(loop, start_us, end_us, kept=True)
        before = await self.store.last_before(loop, start_us, hold)
        self.full_reads += 1
        return self._keep(
            loop, CachedWindow(start_us, end_us, series, before, end_us, hold, oldest_pv_us)
        )

    def _keep(self, loop: LoopRow, c: CachedWindow) -> LoopWindow:
        """Cache ``c`` (dropping the least recently used loops beyond the bound) and align it."""
        self._loops[loop.name] = c
        self.nbytes += c.nbytes
        while self._loops and self.nbytes > self.max_bytes:
            self.nbytes -= self._loops.popitem(last=False)[1].nbytes
        return align(c.series, c.start_us, c.end_us, None, c.before, c.hold)


def _before(
    t: NDArray[np.int64], v: NDArray[np.float64], end_us: int
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    k = int(np.searchsorted(t, end_us, side="left"))
    return t[:k], v[:k]
