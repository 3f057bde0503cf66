"""Each valve's stiction trend is stored with its estimates (``storage/trends.py``), on a real
SQLite file and a real PostgreSQL database, so the report only reads it."""

from __future__ import annotations

import asyncio
import sqlite3
from dataclasses import replace
from pathlib import Path

from helpers import T0, verdict_of

from plantcheck.storage.database import head_revision, upgrade
from plantcheck.storage.results import record_verdict
from plantcheck.storage.store import Store
from plantcheck.storage.trends import read_trends

WEEK = 7 * 24 * 3_600_000_000


def test_a_growing_stickband_is_projected_to_its_limit(db_url: str) -> None:
    async def run() -> None:
        store = await Store.open(db_url)
        try:
            row = await store.ensure_loop("FV1", signals=("pv", "op"))
            for k in range(5):  # S grows 0.2 % a week from 2 %, the valve's limit is 4 %
                v = verdict_of(row, T0 + k * WEEK, "stiction", 2.0 + 0.2 * k, 1.0)
                await record_verdict(store, replace(v, stiction_limit=4.0))
            trend = (await read_trends(store))["FV1"]
            assert trend.method == "hammerstein" and trend.used == 5 and trend.limit == 4.0
            assert trend.slope_per_week is not None and abs(trend.slope_per_week - 0.2) < 1e-6
            assert not trend.above_limit and trend.projected_crossing_us is not None
            assert T0 + 5 * WEEK < trend.projected_crossing_us < T0 + 15 * WEEK
            assert trend.computed_us == T0 + 4 * WEEK
        finally:
            await store.close()

    asyncio.run(run())


def test_migration_adds_the_trend_table_to_an_older_database(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    url = f"sqlite+aiosqlite:///{path}"
    upgrade(url)
    con = sqlite3.connect(path)
    con.executescript(
        "DROP TABLE stiction_trends; UPDATE alembic_version SET version_num = '0005';"
    )
    con.close()
    upgrade(url)
    con = sqlite3.connect(path)
    assert con.execute("SELECT version_num FROM alembic_version").fetchone()[0] == head_revision()
    assert con.execute("SELECT count(*) FROM stiction_trends").fetchone()[0] == 0
    con.close()
