"""What the distributed roles share through the store (issue 28): a loop's recent history for
any diagnosis worker, the sources' health reports, and the scheduler lock (PostgreSQL)."""

from __future__ import annotations

import asyncio

import pytest
from helpers import verdict_of

from plantcheck.core.source_health import SourceHealth
from plantcheck.storage.leader_lock import LeaderLock
from plantcheck.storage.results import recent_history, record_verdict
from plantcheck.storage.source_health import report_health, reported_health
from plantcheck.storage.store import Store

H = 3_600_000_000


def test_recent_history_gives_each_loop_its_newest_causes(db_url: str) -> None:
    async def run() -> None:
        store = await Store.open(db_url)
        try:
            a = await store.ensure_loop("A", signals=("pv", "op"))
            b = await store.ensure_loop("B", signals=("pv", "op"))
            for i, cause in enumerate(["ok", "stiction", "stiction", "stiction"]):
                await record_verdict(
                    store, verdict_of(a, (i + 1) * H, cause, S=2.0 if i == 2 else None)
                )
            hist = await recent_history(store, [a.id, b.id], 2)
            assert hist[a.id].causes == [("stiction", 4 * H), ("stiction", 3 * H)]
            assert hist[a.id].last_window_end_us == 4 * H
            assert hist[a.id].last_identified_us == 3 * H  # the reliable estimate's window end
            assert hist[b.id].causes == [] and hist[b.id].last_identified_us is None
        finally:
            await store.close()

    asyncio.run(run())


def test_health_reports_replace_their_sources_only(db_url: str) -> None:
    async def run() -> None:
        store = await Store.open(db_url)
        try:
            up = SourceHealth("u1", "opcua", "up", 10, 20, 0, "")
            down = SourceHealth("u2", "modbus", "down", 30, None, 3, "timed out")
            await report_health(store, "edge1", [up], 100)
            await report_health(store, "edge2", [down], 110)
            await report_health(store, "edge1", [up], 200)  # a newer report of u1 only
            got = await reported_health(store)
            assert got["u1"].reported_us == 200 and got["u1"].collector == "edge1"
            assert got["u2"].health == down and got["u2"].reported_us == 110
        finally:
            await store.close()

    asyncio.run(run())


def test_one_holder_of_the_scheduler_lock(db_url: str) -> None:
    if not db_url.startswith("postgresql"):
        pytest.skip("the scheduler lock is a PostgreSQL advisory lock (SQLite has one process)")

    async def run() -> None:
        first, second = await Store.open(db_url), await Store.open(db_url)
        try:
            a, b = LeaderLock(first), LeaderLock(second)
            assert await a.try_acquire() and await a.still_held()
            assert not await b.try_acquire() and not b.held
            await a.release()
            assert await b.try_acquire()  # released: the standby takes it
            await b.release()
        finally:
            await first.close()
            await second.close()

    asyncio.run(run())


def test_roles_starting_together_map_the_same_loops_once(db_url: str) -> None:
    """A service, its workers and collectors start at once on one database: each maps the
    site's sources and loops, and the losers of the insert race update instead of failing."""
    from helpers import one_loop_config

    cfg = one_loop_config()

    async def run() -> None:
        stores = [await Store.open(db_url) for _ in range(4)]
        try:
            maps = await asyncio.gather(*(s.sync_config(cfg) for s in stores))
            assert all(m == maps[0] for m in maps) and list(maps[0]) == [cfg.loop[0].id]
        finally:
            for s in stores:
                await s.close()

    asyncio.run(run())
