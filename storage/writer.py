"""Batched, outage-proof sample writer between the connectors and the store.

Connectors call ``put()`` (never blocks, never raises). A background task commits what arrived
about once a second (``commit_interval_s``). When the store fails, the batch goes to the local
``DurableBuffer`` and the writer retries with backoff; once the store answers again the buffer
is written back first, oldest first, idempotently (same tag and timestamp stored once), then
new samples. A failure is logged once and the recovery once. On SQLite the WAL is checkpointed
every ``checkpoint_every_s``. Every hour the writer rolls its own tags' complete hours up into
``sample_hours`` (``rollups.roll_up``: the long trends), then deletes samples older than
``retention_s`` and roll-ups older than ``rollup_retention_s``: in a task of its own beside the
commits, ``housekeeping_slice`` tags at a time, so a large site's housekeeping never holds
samples back.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from plantcheck.core.samples import Sample
from plantcheck.storage.buffer import DurableBuffer
from plantcheck.storage.rollups import purge_hours, roll_up
from plantcheck.storage.store import Store

log = logging.getLogger("plantcheck.storage")


@dataclass
class WriterStats:
    """Counters exposed by ``/metrics``: samples received and stored, batches, drops."""

    received: int = 0
    stored: int = 0
    batches: int = 0
    store_failures: int = 0
    store_up: bool = True
    last_commit_s: float = 0.0
    commit_durations: list[float] = field(default_factory=list)


class SampleWriter:
    """Owns the in-memory queue, the durable buffer and the commit task."""

    def __init__(
        self,
        store: Store,
        buffer_path: Path,
        *,
        buffer_max_samples: int = 5_000_000,
        commit_interval_s: float = 1.0,
        batch_max: int = 50_000,
        checkpoint_every_s: float = 300.0,
        retention_s: float | None = None,
        purge_every_s: float = 3600.0,
        rollup_tags: Sequence[int] = (),
        rollup_retention_s: float | None = None,
        housekeeping_slice: int = 200,
        housekeeping_pause_s: float = 0.2,
        housekeeping_share: float = 0.2,
    ) -> None:
        self.store = store
        self.buffer = DurableBuffer(buffer_path, buffer_max_samples)
        self.commit_interval_s = commit_interval_s
        self.batch_max = batch_max
        self.checkpoint_every_s = checkpoint_every_s
        self.retention_s = retention_s
        self.purge_every_s = purge_every_s
        self._own = frozenset(rollup_tags)
        """The tags this writer rolls up: its own (each collector and the service theirs)."""
        self.rollup_retention_s = rollup_retention_s
        self.housekeeping_slice = housekeeping_slice
        self.housekeeping_pause_s = housekeeping_pause_s
        self.housekeeping_share = housekeeping_share
        """Share of the time the housekeeping may keep the database busy (40,000 tags: about
        10 minutes of every hour at a fifth of a connection)."""
        self._chores: list[int] = []
        """Tags still to housekeep this hour."""
        self._purged = 0
        self.stats = WriterStats()
        self._pending: list[Sample] = []
        self._task: asyncio.Task[None] | None = None
        self._house_task: asyncio.Task[None] | None = None
        self._stop = asyncio.Event()
        self._retry_s = commit_interval_s
        self._next_try = 0.0

    @property
    def dropped(self) -> int:
        """Samples lost because the durable buffer was full."""
        return self.buffer.dropped

    @property
    def housekeeping_pending(self) -> int:
        """Tags still to housekeep this hour."""
        return len(self._chores)

    @property
    def depth(self) -> int:
        """Samples waiting: in memory plus in the durable buffer."""
        return len(self._pending) + len(self.buffer)

    def put(self, rows: Sequence[Sample]) -> None:
        """Hand samples over (non-blocking)."""
        self._pending.extend(rows)
        self.stats.received += len(rows)
        if len(self._pending) > 4 * self.batch_max:  # store slow or down: keep memory bounded
            self._spill()

    def _spill(self) -> None:
        rows, self._pending = self._pending, []
        lost = self.buffer.append(rows)
        if lost:
            log.error("durable buffer full: dropped %d samples (%d in all)", lost, self.dropped)

    async def _write(self, rows: Sequence[Sample]) -> None:
        t0 = time.perf_counter()
        await self.store.write_samples(rows)
        dt = time.perf_counter() - t0
        self.stats.stored += len(rows)
        self.stats.batches += 1
        self.stats.last_commit_s = dt
        self.stats.commit_durations = [*self.stats.commit_durations[-99:], dt]

    async def flush(self) -> None:
        """Write everything waiting now (buffer first); on failure keep it in the buffer."""
        if time.monotonic() < self._next_try:
            if self._pending:
                self._spill()
            return
        try:
            while len(self.buffer):
                seq, rows = self.buffer.peek(self.batch_max)
                await self._write(rows)
                self.buffer.remove_through(seq)
            while self._pending:
                rows = self._pending[: self.batch_max]
                await self._write(rows)
                del self._pending[: len(rows)]
        except Exception as exc:
            self.stats.store_failures += 1
            if self.stats.store_up:
                log.error("store unreachable, buffering samples locally: %s", exc)
            self.stats.store_up = False
            if self._pending:
                self._spill()
            self._next_try = time.monotonic() + self._retry_s
            self._retry_s = min(self._retry_s * 2, 30.0)
            return
        if not self.stats.store_up:
            log.warning("store reachable again; buffered samples written")
        self.stats.store_up = True
        self._retry_s = self.commit_interval_s

    async def housekeep(self, tag_ids: Sequence[int]) -> tuple[int, int]:
        """The hourly housekeeping of ``tag_ids``: roll this writer's own ones up by the hour
        (before their samples go), then apply the retention of samples and of roll-ups;
        returns (hours rolled up, samples deleted)."""
        now_us = time.time_ns() // 1000
        mine = [t for t in tag_ids if t in self._own]
        hours = await roll_up(self.store, now_us, mine) if mine else 0
        deleted = 0
        if self.retention_s is not None:
            deleted = await self.store.purge(now_us - int(self.retention_s * 1e6), tag_ids)
        if self.rollup_retention_s is not None:
            await purge_hours(self.store, now_us - int(self.rollup_retention_s * 1e6), tag_ids)
        return hours, deleted

    async def _housekeep_slice(self) -> None:
        """One slice of the hourly housekeeping: a site of 40,000 tags takes minutes of it.

        The slice's tags leave the list once their work is over (done, failed or cancelled),
        so ``housekeeping_pending`` counts a slice still under way."""
        chunk = self._chores[: self.housekeeping_slice]
        try:
            _, deleted = await self.housekeep(chunk)
        finally:
            self._chores = self._chores[len(chunk) :]
        self._purged += deleted
        if not self._chores and self._purged and self.retention_s is not None:
            log.info(
                "retention: deleted %d samples older than %.0f days",
                self._purged,
                self.retention_s / 86400,
            )

    async def _run(self) -> None:
        last_checkpoint = time.monotonic()
        # commits on a fixed cadence: waiting a whole interval after each commit would add the
        # commit's own time to every sample's wait (ingest lag, issue 28)
        due = time.monotonic()
        while not self._stop.is_set():
            due = max(due + self.commit_interval_s, time.monotonic())
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stop.wait(), due - time.monotonic())
            await self.flush()
            if time.monotonic() - last_checkpoint > self.checkpoint_every_s and self.stats.store_up:
                with contextlib.suppress(Exception):
                    await self.store.checkpoint()
                last_checkpoint = time.monotonic()

    async def _housekeeping(self) -> None:
        """The hourly housekeeping beside the commits, on its own connections: a slice of
        tags at a time with a pause between slices, so that commits never wait for it."""
        last = 0.0
        while not self._stop.is_set():
            if time.monotonic() - last > self.purge_every_s and self.stats.store_up:
                last = time.monotonic()
                with contextlib.suppress(Exception):
                    self._chores, self._purged = await self.store.tag_ids(), 0
            while self._chores and not self._stop.is_set():
                t0 = time.monotonic()
                if self.stats.store_up:
                    with contextlib.suppress(Exception):
                        await self._housekeep_slice()
                # busy at most ``housekeeping_share`` of the time: the database serves the
                # commits first
                worked = time.monotonic() - t0
                pause = max(self.housekeeping_pause_s, worked / self.housekeeping_share - worked)
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._stop.wait(), pause)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stop.wait(), self.commit_interval_s)

    def start(self) -> None:
        loop = asyncio.get_running_loop()
        self._task = loop.create_task(self._run())
        self._house_task = loop.create_task(self._housekeeping())

    async def stop(self) -> None:
        """Commit what is left (or keep it in the durable buffer) and stop."""
        self._stop.set()
        if self._house_task is not None:
            # idempotent work: a slice cut short is done again next hour
            self._house_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._house_task
        if self._task is not None:
            await self._task
        self._next_try = 0.0
        await self.flush()
        if self._pending:
            self._spill()
        self.buffer.close()
