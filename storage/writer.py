"""Batched, outage-proof sample writer between the connectors and the store.

Connectors call ``put()`` (never blocks, never raises). A background task commits what arrived
about once a second (``commit_interval_s``). When the store fails, the batch goes to the local
``DurableBuffer`` and the writer retries with backoff (at most ``retry_max_s``); once the store
answers again the buffer is written back first, oldest first, idempotently (same tag and
timestamp stored once), then new samples. A failure is logged once and the recovery once. On
SQLite the WAL is checkpointed every ``checkpoint_every_s``. Every hour the writer rolls its own
tags' complete hours up into ``sample_hours`` (``rollups.roll_up``: the long trends), then
deletes samples older than ``retention_s`` and roll-ups older than ``rollup_retention_s``: in a
task of its own beside the commits, ``housekeeping_slice`` tags at a time, so a large site's
housekeeping never holds samples back.

When the store and the buffer fail together (one disk, full or read-only: issue 45), samples
wait in memory, at most ``memory_max_samples``; what arrives past that is dropped and counted,
and a gap marker (``BadNoCommunication``) is stored at each tag's first dropped sample so the
history shows the hole. Both sides are tried again on the backoff clock and whichever answers
first takes the samples. The commit task never ends on an error: an unexpected one is logged
once and the next commit tried. At ``stop()`` every sample that reached neither side is
counted in the log (``lost_at_stop``).
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
from plantcheck.core.status_codes import BAD_NO_COMMUNICATION
from plantcheck.storage.buffer import BufferUnavailableError, DurableBuffer
from plantcheck.storage.rollups import purge_hours, roll_up
from plantcheck.storage.store import Store

log = logging.getLogger("plantcheck.storage")


def _now_us() -> int:
    return time.time_ns() // 1000


HOUSEKEEPING_STOP_S = 5.0
"""How long a stop waits for the housekeeping slice under way (s)."""


@dataclass
class WriterStats:
    """Counters exposed by ``/metrics``, ``/readyz`` and ``GET /api/v1/storage``."""

    received: int = 0
    stored: int = 0
    batches: int = 0
    store_failures: int = 0
    store_up: bool = True
    """The last commit to the store succeeded (reads may work while writes fail)."""
    buffer_up: bool = True
    """The durable buffer took the last samples handed to it (or none were needed)."""
    buffer_failures: int = 0
    dropped_in_memory: int = 0
    """Samples dropped because the store and the buffer failed and memory was full."""
    lost_at_stop: int = 0
    """Samples that reached neither the store nor the buffer when the writer stopped."""
    store_error: str = ""
    """The most recent commit failure, empty while commits succeed."""
    buffer_error: str = ""
    """The most recent buffer failure, empty while the buffer works."""
    store_down_since_us: int | None = None
    buffer_down_since_us: int | None = None
    last_commit_s: float = 0.0
    commit_durations: list[float] = field(default_factory=list)


def _gap_markers(rows: Sequence[Sample], now_us: int) -> dict[int, Sample]:
    """Per tag, a gap marker at the first of ``rows`` (the dropped samples)."""
    first: dict[int, int] = {}
    for r in rows:
        if r.tag_id not in first or r.ts_us < first[r.tag_id]:
            first[r.tag_id] = r.ts_us
    return {t: Sample(t, ts, now_us, None, BAD_NO_COMMUNICATION) for t, ts in first.items()}


class SampleWriter:
    """Owns the in-memory queue, the durable buffer and the commit task."""

    def __init__(
        self,
        store: Store,
        buffer_path: Path,
        *,
        buffer_max_samples: int = 5_000_000,
        memory_max_samples: int = 500_000,
        commit_interval_s: float = 1.0,
        retry_max_s: float = 5.0,
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
        self.memory_max_samples = memory_max_samples
        self.commit_interval_s = commit_interval_s
        self.retry_max_s = retry_max_s
        """Longest wait between two tries of a failing store or buffer: writing resumes at
        most this long after the disk or database recovers (s)."""
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
        self._markers: dict[int, Sample] = {}
        """Gap markers of dropped samples, per tag, not yet stored or buffered."""
        self._task: asyncio.Task[None] | None = None
        self._house_task: asyncio.Task[None] | None = None
        self._stop = asyncio.Event()
        self._retry_s = commit_interval_s
        self._next_try = 0.0
        self._buffer_retry_s = commit_interval_s
        self._buffer_next_try = 0.0
        self._unexpected_logged = False
        self._dropping = False
        """Samples are being dropped now (logged once per episode)."""

    @property
    def dropped(self) -> int:
        """Samples lost: the durable buffer full, or memory full while both sides failed."""
        return self.buffer.dropped + self.stats.dropped_in_memory

    @property
    def held(self) -> int:
        """Samples held in memory because the store does not take them (0 while it does: the
        second's batch on its way is not held)."""
        return 0 if self.stats.store_up else len(self._pending)

    @property
    def housekeeping_pending(self) -> int:
        """Tags still to housekeep this hour."""
        return len(self._chores)

    @property
    def depth(self) -> int:
        """Samples waiting: in memory plus in the durable buffer."""
        return len(self._pending) + len(self.buffer)

    @property
    def backlog(self) -> int:
        """Samples waiting because the store did not take them: in the durable buffer, and in
        memory while commits fail (not the second's batch on its way, issue 47)."""
        return len(self.buffer) + self.held

    @property
    def writing(self) -> bool:
        """Samples reach the disk: the store commits, or the buffer takes what it cannot."""
        return self.stats.store_up or self.stats.buffer_up

    def put(self, rows: Sequence[Sample]) -> None:
        """Hand samples over (non-blocking)."""
        self.stats.received += len(rows)
        if self.writing:
            self._pending.extend(rows)
            if len(self._pending) > 4 * self.batch_max:  # store slow or down: bound memory
                self._spill()
            return
        room = max(0, self.memory_max_samples - len(self._pending))
        self._pending.extend(rows[:room])
        if len(rows) > room:
            self._drop(rows[room:])

    def _drop(self, rows: Sequence[Sample]) -> None:
        """Count ``rows`` as lost and keep a gap marker per tag at its first lost sample."""
        if not self._dropping:
            self._dropping = True
            log.error(
                "store and durable buffer both failing and %d samples held in memory "
                "(storage.memory_max_samples): dropping new samples until one recovers",
                len(self._pending),
            )
        self.stats.dropped_in_memory += len(rows)
        for tag, marker in _gap_markers(rows, _now_us()).items():
            if tag not in self._markers:
                self._markers[tag] = marker

    def _spill(self) -> bool:
        """Move the samples held in memory (and gap markers) to the durable buffer; False
        (and kept in memory) while the buffer fails."""
        if not self._pending and not self._markers:
            return True
        if not self.stats.buffer_up and time.monotonic() < self._buffer_next_try:
            return False
        rows = [*self._markers.values(), *self._pending]
        try:
            lost = self.buffer.append(rows)
        except BufferUnavailableError as exc:
            self._buffer_failed(exc)
            return False
        self._markers = {}
        if lost:
            # the buffer kept the oldest: the hole starts at each tag's first sample it refused
            self._markers = _gap_markers(rows[len(rows) - lost :], _now_us())
        self._pending = []
        self._buffer_recovered()
        if lost:
            log.error("durable buffer full: dropped %d samples (%d in all)", lost, self.dropped)
        return True

    def _buffer_failed(self, exc: Exception) -> None:
        st = self.stats
        st.buffer_failures += 1
        st.buffer_error = str(exc)
        if st.buffer_up:
            st.buffer_up = False
            st.buffer_down_since_us = _now_us()
            log.error(
                "durable buffer failing (%s): holding samples in memory (at most %d) and "
                "trying the store and the buffer again",
                exc,
                self.memory_max_samples,
            )
        self._buffer_next_try = time.monotonic() + self._buffer_retry_s
        self._buffer_retry_s = min(self._buffer_retry_s * 2, self.retry_max_s)

    def _buffer_recovered(self) -> None:
        st = self.stats
        if not st.buffer_up:
            log.warning("durable buffer writable again")
        st.buffer_up, st.buffer_error, st.buffer_down_since_us = True, "", None
        self._dropping = False
        self._buffer_retry_s = self.commit_interval_s

    async def _write(self, rows: Sequence[Sample]) -> None:
        t0 = time.perf_counter()
        await self.store.write_samples(rows)
        dt = time.perf_counter() - t0
        self.stats.stored += len(rows)
        self.stats.batches += 1
        self.stats.last_commit_s = dt
        self.stats.commit_durations = [*self.stats.commit_durations[-99:], dt]

    async def _drain_buffer(self) -> None:
        """Write the durable buffer back to the store, oldest first. A buffer that cannot be
        read or emptied is left for later (its samples are written again then: idempotent)."""
        if not len(self.buffer):
            return
        if not self.stats.buffer_up and time.monotonic() < self._buffer_next_try:
            return
        try:
            while len(self.buffer):
                seq, rows = self.buffer.peek(self.batch_max)
                await self._write(rows)
                self.buffer.remove_through(seq)
        except BufferUnavailableError as exc:
            self._buffer_failed(exc)
            return
        self._buffer_recovered()

    async def _commit(self) -> None:
        """Buffer first, then gap markers, then what is held in memory; raises on failure."""
        await self._drain_buffer()
        if self._markers:
            await self._write(list(self._markers.values()))
            self._markers = {}
        while self._pending:
            rows = self._pending[: self.batch_max]
            await self._write(rows)
            del self._pending[: len(rows)]

    async def flush(self) -> None:
        """Write everything waiting now (buffer first); on failure keep it in the buffer, or
        in memory while the buffer fails too."""
        st = self.stats
        if time.monotonic() < self._next_try:
            if self._pending or self._markers:
                self._spill()
            return
        try:
            await self._commit()
        except Exception as exc:
            st.store_failures += 1
            st.store_error = str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__
            if st.store_up:
                st.store_up = False
                st.store_down_since_us = _now_us()
                log.error("store not taking samples, buffering them locally: %s", st.store_error)
            self._spill()
            self._next_try = time.monotonic() + self._retry_s
            self._retry_s = min(self._retry_s * 2, self.retry_max_s)
            return
        if not st.store_up:
            log.warning("store taking samples again; buffered samples written")
        st.store_up, st.store_error, st.store_down_since_us = True, "", None
        self._dropping = False
        self._retry_s = self.commit_interval_s
        if not st.buffer_up and not (self._pending or self._markers or len(self.buffer)):
            # nothing waits: whatever failed in the buffer no longer holds anything back
            self._buffer_recovered()

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
            try:
                await self.flush()
            except Exception:
                # the commit task must outlive any bug: samples keep arriving
                if not self._unexpected_logged:
                    log.exception("sample writer: unexpected error; retrying")
                    self._unexpected_logged = True
            if time.monotonic() - last_checkpoint > self.checkpoint_every_s and self.stats.store_up:
                with contextlib.suppress(Exception):
                    await self.store.checkpoint()
                last_checkpoint = time.monotonic()

    async def _housekeeping(self) -> None:
        """The hourly housekeeping beside the commits, on its own connections: a slice of
        tags at a time with a pause between slices, so that commits never wait for it."""
        # the first round at start, whatever the machine's uptime (``last = 0.0`` made it run at
        # start only on a machine up for more than ``purge_every_s``)
        last = -float("inf")
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
        """Commit what is left (or keep it in the durable buffer) and stop; samples that reach
        neither are counted and logged, never dropped silently."""
        self._stop.set()
        if self._house_task is not None:
            # it ends after its slice (``_stop``): cancelled inside one, the database driver's
            # thread would answer a loop that may have closed by then. A slice that takes too
            # long is cut short (idempotent work: done again next hour)
            try:
                await asyncio.wait_for(asyncio.shield(self._house_task), HOUSEKEEPING_STOP_S)
            except TimeoutError:
                self._house_task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await self._house_task
        if self._task is not None:
            with contextlib.suppress(Exception):
                await self._task
        self._next_try = 0.0
        self._buffer_next_try = 0.0
        with contextlib.suppress(Exception):
            await self.flush()
        if self._pending or self._markers:
            self._buffer_next_try = 0.0
            self._spill()
        if self._pending:
            self.stats.lost_at_stop = len(self._pending)
            log.error(
                "stopping with %d samples that neither the store (%s) nor the durable buffer "
                "(%s) would take: they are lost",
                len(self._pending),
                self.stats.store_error or "up",
                self.stats.buffer_error or "up",
            )
            self._pending = []
        elif len(self.buffer):
            log.warning(
                "stopping with %d samples in the durable buffer %s: written to the store at the "
                "next start",
                len(self.buffer),
                self.buffer.path,
            )
        self.buffer.close()
