"""The sample writer when its disk fills (issue 45), on a real SQLite file on a real tmpfs.

The database and the durable buffer on one small filesystem that fills: the writer holds the
samples in memory (bounded, counted past the bound, a gap marker where they were dropped),
says so in its stats, never ends, and writes everything once the disk is freed. The database
full with the buffer on another filesystem: nothing is held in memory, the buffer takes it.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from helpers import one_loop_config
from smalldisk import SmallDisk, small_disk

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import BAD_NO_COMMUNICATION, GOOD
from plantcheck.storage.database import upgrade
from plantcheck.storage.store import Store
from plantcheck.storage.writer import SampleWriter


def _rows(tag: int, first: int, n: int) -> list[Sample]:
    t0 = time.time_ns() // 1000
    return [Sample(tag, t0 + k, t0 + k, float(k), GOOD) for k in range(first, first + n)]


async def _until(cond: object, timeout_s: float = 15.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():  # type: ignore[operator]
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.1)


def _store_url(disk: SmallDisk) -> str:
    url = f"sqlite+aiosqlite:///{disk.path / 'store.db'}"
    upgrade(url)
    return url


async def _writer(url: str, buffer: Path, **kw: Any) -> tuple[Store, int, SampleWriter]:
    """The store at ``url``, FIC1's PV tag and a started writer buffering to ``buffer``."""
    store = await Store.open(url)
    tag = (await store.sync_config(one_loop_config()))["FIC1"].tags["pv"]
    w = SampleWriter(store, buffer, commit_interval_s=0.1, **kw)
    w.start()
    return store, tag, w


async def _feed_until(w: SampleWriter, tag: int, first: int, done: Callable[[], bool]) -> int:
    """Hand over 500 samples every 0.1 s until ``done()``; the next sample's number."""
    sent = first
    while not done():
        w.put(_rows(tag, sent, 500))
        sent += 500
        await asyncio.sleep(0.1)
        assert sent < 200_000, "the full disk never refused a write"
    return sent


def test_one_full_disk_holds_samples_in_memory_and_writes_them_when_freed(
    tmp_path: Path,
) -> None:
    with small_disk(tmp_path / "disk") as disk:
        url = _store_url(disk)

        async def body() -> None:
            store, tag, w = await _writer(url, disk.path / "buffer.db", retry_max_s=1)
            w.put(_rows(tag, 0, 100))
            await _until(lambda: w.stats.stored >= 100)
            disk.fill()
            # both fail within a few commits
            sent = await _feed_until(w, tag, 100, lambda: not w.writing)
            assert w.held > 0 and w.stats.store_error
            assert w._task is not None and not w._task.done()  # the commit task lives on
            for _ in range(5):  # arriving while both fail: held, nothing dropped yet
                w.put(_rows(tag, sent, 100))
                sent += 100
                await asyncio.sleep(0.1)
            assert w.dropped == 0 and w.held > 0
            # the back-off, doubled at every failed try, stays within retry_max_s: both are
            # tried again within a second of the disk being freed (how soon writing resumes
            # is measured by benchmarks/disk_faults.py, not asserted on this machine's clock)
            now = time.monotonic()
            assert w._next_try - now <= 1.0 and w._buffer_next_try - now <= 1.0
            disk.free()
            await _until(
                lambda: w.stats.store_up and w.held == 0 and len(w.buffer) == 0, timeout_s=60.0
            )
            assert w.stats.buffer_up
            await w.stop()
            assert await store.count_samples([tag]) == sent
            await store.close()

        asyncio.run(body())


def test_memory_is_bounded_and_a_drop_is_counted_and_marked(tmp_path: Path) -> None:
    with small_disk(tmp_path / "disk") as disk:
        url = _store_url(disk)

        async def body() -> None:
            store, tag, w = await _writer(
                url, disk.path / "buffer.db", retry_max_s=1, memory_max_samples=2000
            )
            disk.fill()
            sent = await _feed_until(w, tag, 0, lambda: not w.writing)
            held = w.held
            w.put(_rows(tag, sent, 5000))  # past the bound: dropped, counted, marked
            sent += 5000
            assert w.held == 2000 and w.dropped == 5000 - (2000 - held)
            disk.free()
            await _until(lambda: w.stats.store_up and w.held == 0 and len(w.buffer) == 0)
            await w.stop()
            kept = await store.count_samples([tag])
            markers = await store._fetch(
                "SELECT count(*) FROM samples WHERE tag_id = ? AND status = ?",
                tag,
                BAD_NO_COMMUNICATION,
            )
            await store.close()
            assert int(markers[0][0]) == 1
            assert kept == sent - w.dropped + 1

        asyncio.run(body())


def test_a_full_database_with_the_buffer_elsewhere_loses_nothing(tmp_path: Path) -> None:
    with small_disk(tmp_path / "disk") as disk:
        url = _store_url(disk)

        async def body() -> None:
            store, tag, w = await _writer(url, tmp_path / "buffer.db", retry_max_s=1)
            disk.fill()
            sent = await _feed_until(w, tag, 0, lambda: not w.stats.store_up)
            await _until(lambda: w.held == 0)  # spilled to the buffer on the other disk
            assert w.stats.buffer_up and len(w.buffer) > 0 and w.dropped == 0
            assert await store.ping()  # reads still work: only the writes tell
            disk.free()
            await _until(lambda: w.stats.store_up and len(w.buffer) == 0)
            await w.stop()
            assert await store.count_samples([tag]) == sent
            await store.close()

        asyncio.run(body())


def test_stopping_while_nothing_takes_samples_says_how_many_are_lost(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with small_disk(tmp_path / "disk") as disk:
        url = _store_url(disk)

        async def body() -> int:
            store, tag, w = await _writer(url, disk.path / "buffer.db")
            disk.fill()
            await _feed_until(w, tag, 0, lambda: not w.writing)
            held = w.held
            await w.stop()  # must not raise
            await store.close()
            assert w.stats.lost_at_stop == held > 0
            return held

        with caplog.at_level(logging.ERROR, logger="plantcheck.storage"):
            held = asyncio.run(body())
        assert f"stopping with {held} samples" in caplog.text


def test_a_database_and_buffer_on_one_disk_are_told_apart_from_two(tmp_path: Path) -> None:
    from plantcheck.service.ingest import shares_a_disk

    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    assert shares_a_disk(url, tmp_path / "buffer.db")
    assert not shares_a_disk("postgresql+asyncpg://u@127.0.0.1/db", tmp_path / "buffer.db")
    with small_disk(tmp_path / "disk") as disk:
        assert not shares_a_disk(url, disk.path / "buffer.db")
