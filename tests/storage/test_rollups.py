"""Hourly roll-ups (``storage/rollups.py``, issue 28): the long trends kept after the samples are
purged, on a real SQLite file and a real PostgreSQL database."""

from __future__ import annotations

import asyncio
import sqlite3
import time
from pathlib import Path

import pytest

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import BAD_SENSOR_FAILURE, GOOD
from plantcheck.storage.database import head_revision, upgrade
from plantcheck.storage.rollups import HOUR_US, purge_hours, read_hours, roll_up
from plantcheck.storage.store import Store
from plantcheck.storage.writer import SampleWriter

T0 = 1_700_000_000 // 3600 * HOUR_US  # a whole hour (µs)
MIN = 60_000_000


def _pv(tag: int, minute: int, value: float | None, status: int = GOOD) -> Sample:
    ts = T0 + minute * MIN
    return Sample(tag, ts, ts, value, status)


def test_hours_roll_up_outlive_the_samples_and_take_late_ones(db_url: str) -> None:
    async def run() -> None:
        store = await Store.open(db_url)
        try:
            loop = await store.ensure_loop("FIC1", signals=("pv", "op"))
            pv, op = loop.tags["pv"], loop.tags["op"]
            rows = [_pv(pv, m, float(m)) for m in range(0, 200, 10)]  # 3 h 20 min
            rows.append(_pv(pv, 5, None, BAD_SENSOR_FAILURE))  # Bad: not rolled up
            rows += [_pv(op, m, 40.0) for m in range(0, 120, 30)]
            await store.write_samples(rows)

            # only complete hours: [T0, T0 + 3 h) at 3 h 20 min
            assert await roll_up(store, T0 + 200 * MIN, [pv, op]) == 5
            hours = await read_hours(store, loop)
            by = {(h.signal, (h.hour_us - T0) // HOUR_US): h for h in hours}
            assert sorted(by) == [("op", 0), ("op", 1), ("pv", 0), ("pv", 1), ("pv", 2)]
            first = by[("pv", 0)]
            assert (first.n, first.mean, first.low, first.high) == (6, 25.0, 0.0, 50.0)
            assert by[("op", 1)].n == 2 and by[("op", 1)].mean == pytest.approx(40.0)
            assert [h.signal for h in await read_hours(store, loop, signals=["op"])] == ["op"] * 2

            # a late sample (a collector's buffer) in the last rolled hour is taken on the next
            # roll-up, and rolling up again changes nothing else
            await store.write_samples([_pv(pv, 125, 1000.0)])
            await roll_up(store, T0 + 200 * MIN, [pv, op])
            pv_hours = await read_hours(store, loop, signals=["pv"])
            late = {(h.hour_us - T0) // HOUR_US: h for h in pv_hours}
            assert late[2].n == 7 and late[2].high == 1000.0
            assert late[0] == first

            # the samples go (retention), the hours stay
            await store.purge(T0 + 4 * HOUR_US)
            assert len(await read_hours(store, loop, T0, T0 + HOUR_US)) == 2
            # a roll-up after the purge re-reads the OP's last hour, where only its newest
            # sample is left: that remnant does not replace the hour's summary
            await roll_up(store, T0 + 200 * MIN, [pv, op])
            kept = {
                (h.signal, (h.hour_us - T0) // HOUR_US): h for h in await read_hours(store, loop)
            }
            assert kept[("op", 1)] == by[("op", 1)] and kept[("pv", 2)] == late[2]
            # and go in their own time
            assert await purge_hours(store, T0 + HOUR_US) == 2
            assert {h.hour_us for h in await read_hours(store, loop)} == {
                T0 + HOUR_US,
                T0 + 2 * HOUR_US,
            }
        finally:
            await store.close()

    asyncio.run(run())


def test_a_first_roll_up_takes_the_whole_history(db_url: str) -> None:
    async def run() -> None:
        store = await Store.open(db_url)
        try:
            loop = await store.ensure_loop("TIC1", signals=("pv",))
            pv = loop.tags["pv"]
            await store.write_samples([_pv(pv, m, 1.0) for m in range(0, 48 * 60, 60)])
            assert await roll_up(store, T0 + 48 * HOUR_US) == 48  # every tag when None
            assert await roll_up(store, T0 + 48 * HOUR_US) == 2  # the lookback, again
        finally:
            await store.close()

    asyncio.run(run())


def test_migration_adds_the_hour_table_to_an_older_database(tmp_path: Path) -> None:
    """A database from before revision 0005 gets ``sample_hours``, its samples untouched."""
    path = tmp_path / "old.db"
    url = f"sqlite+aiosqlite:///{path}"
    upgrade(url)
    con = sqlite3.connect(path)
    con.executescript("DROP TABLE sample_hours; UPDATE alembic_version SET version_num = '0004';")
    con.close()
    upgrade(url)
    con = sqlite3.connect(path)
    assert con.execute("SELECT version_num FROM alembic_version").fetchone()[0] == head_revision()
    assert con.execute("SELECT count(*) FROM sample_hours").fetchone()[0] == 0
    con.close()


def test_a_slice_under_way_is_still_pending(tmp_path: Path) -> None:
    """``housekeeping_pending`` counts the slice being housekept: the tags left the list
    before their work was done, so a waiter saw 0 and stopped the writer mid-purge (the slice
    test above failed so on a loaded machine: 122 samples left)."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)

    async def run() -> None:
        store = await Store.open(url)
        try:
            loop = await store.ensure_loop("ONE", signals=("pv",))
            writer = SampleWriter(
                store, tmp_path / "buffer.db", retention_s=1800.0, housekeeping_slice=1
            )
            release = asyncio.Event()
            real = writer.housekeep

            async def held(tags: list[int]) -> tuple[int, int]:
                await release.wait()  # the store's own work, once let through
                return await real(tags)

            writer.housekeep = held  # type: ignore[method-assign]
            writer._chores = list(loop.tags.values())
            work = asyncio.create_task(writer._housekeep_slice())
            await asyncio.sleep(0.05)
            assert writer.housekeeping_pending == 1  # under way, not done
            release.set()
            await work
            assert writer.housekeeping_pending == 0
        finally:
            await store.close()

    asyncio.run(run())


def test_the_writer_housekeeps_its_own_tags_in_slices(tmp_path: Path) -> None:
    """Every hour, a few tags between two commits: its own tags rolled up (another collector's
    are not), every tag's old samples purged, the roll-ups kept."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)

    async def run() -> None:
        store = await Store.open(url)
        try:
            mine = await store.ensure_loop("MINE", signals=("pv", "op"))
            other = await store.ensure_loop("OTHER", signals=("pv",))
            now = time.time_ns() // 1000 // HOUR_US * HOUR_US
            rows = [
                Sample(tag, now - 2 * HOUR_US + m * MIN, now, 1.0, GOOD)
                for tag in (*mine.tags.values(), other.tags["pv"])
                for m in range(120)
            ]
            await store.write_samples(rows)
            writer = SampleWriter(
                store,
                tmp_path / "buffer.db",
                commit_interval_s=0.05,
                retention_s=1800.0,
                purge_every_s=0.0,
                rollup_tags=list(mine.tags.values()),
                housekeeping_slice=1,
            )
            writer.start()
            try:
                for _ in range(100):
                    await asyncio.sleep(0.05)
                    if len(await read_hours(store, mine)) == 4 and not writer.housekeeping_pending:
                        break
            finally:
                await writer.stop()
            assert len(await read_hours(store, mine)) == 4  # 2 tags x 2 complete hours
            assert await read_hours(store, other) == []  # another collector's tag
            # the samples older than 30 min are gone (each tag's newest before it kept)
            assert await store.count_samples() <= 3 * 31
        finally:
            await store.close()

    asyncio.run(run())
