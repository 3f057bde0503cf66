"""The cached loop-health table: increments read only the loops diagnosed since the last
refresh, the whole table is read every ``full_every_s``, and the body is always the rows."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

from helpers import verdict_of

from plantcheck.api.loop_table import LoopTable
from plantcheck.storage.database import upgrade
from plantcheck.storage.results import record_verdict
from plantcheck.storage.store import Store

M = 60_000_000


def test_increments_follow_new_verdicts(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)

    async def run() -> None:
        store = await Store.open(url)
        try:
            rows = [await store.ensure_loop(f"L{i}", signals=("pv", "op")) for i in range(5)]
            for i, row in enumerate(rows):
                await record_verdict(store, verdict_of(row, 10**15 + i * M, "ok"))
            table = LoopTable(ttl_s=0.0, full_every_s=3600.0, margin_s=1.0)
            await table._build(store)
            assert [r["cause"] for r in table._rows] == ["ok"] * 5
            await record_verdict(store, verdict_of(rows[1], 10**15 + 10 * M, "stiction", S=2.5))
            await table._build(store)  # an increment: L1 and nothing else re-read
            by_id = {r["id"]: r for r in table._rows}
            assert by_id["L1"]["cause"] == "stiction" and by_id["L1"]["S"] == 2.5
            assert [r["id"] for r in table._rows] == [f"L{i}" for i in range(5)]
            assert json.loads(table._body) == table._rows
            await store.ensure_loop("L9", signals=("pv",))  # never diagnosed: the next full read
            table.full_every_s = 0.0
            await table._build(store)
            assert [r["id"] for r in table._rows][-1] == "L9"
        finally:
            await store.close()

    asyncio.run(run())


def test_a_reader_after_a_new_verdict_gets_it_not_the_table_before(tmp_path: Path) -> None:
    """Polled every 10 s (or at any pace), the table is as fresh as the store: the verdict
    committed before a request is in that request's answer (issue 47: it came one poll late)."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)

    async def run() -> None:
        store = await Store.open(url)
        try:
            row = await store.ensure_loop("L0", signals=("pv", "op"))
            await record_verdict(store, verdict_of(row, 10**15, "ok"))
            table = LoopTable(ttl_s=0.05)
            assert [r["cause"] for r in (await table.get(store))[0]] == ["ok"]
            await record_verdict(store, verdict_of(row, 10**15 + M, "stiction", S=3.0))
            await asyncio.sleep(0.1)  # the poller's next visit, after the table's ttl
            rows, body = await table.get(store)
            assert rows[0]["cause"] == "stiction" and json.loads(body)[0]["S"] == 3.0
        finally:
            await store.close()

    asyncio.run(run())
