"""The time-series store on a real SQLite file and a real PostgreSQL cluster."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest
from helpers import T0, one_loop_config

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import BAD_SENSOR_FAILURE, GOOD
from plantcheck.storage.database import StorageError
from plantcheck.storage.store import Store


def test_write_read_window_idempotent_and_bad_is_null(db_url: str) -> None:
    async def body() -> None:
        store = await Store.open(db_url)
        try:
            loops = await store.sync_config(one_loop_config())
            lp = loops["FIC1"]
            assert set(lp.tags) == {"sp", "pv", "op"}
            n = 600
            rows = []
            for k in range(n):
                ts = T0 + k * 1_000_000
                rows.append(Sample(lp.tags["sp"], ts, ts, 50.0, GOOD))
                rows.append(Sample(lp.tags["op"], ts, ts, 40.0 + k % 7, GOOD))
                if 100 <= k < 130:
                    continue  # a gap in PV
                if k == 200:
                    rows.append(Sample(lp.tags["pv"], ts, ts, None, BAD_SENSOR_FAILURE))
                else:
                    rows.append(Sample(lp.tags["pv"], ts, ts, 50.0 + 0.01 * k, GOOD))
            await store.write_samples(rows)
            await store.write_samples(rows[:500])  # a replay stores nothing twice
            assert await store.count_samples() == len(rows)
            w = await store.read_window(lp, T0, T0 + n * 1_000_000)
            assert w.sample_time_s == pytest.approx(1.0)
            assert w["pv"].size == n
            assert np.isnan(w["pv"][100:130]).all() and np.isnan(w["pv"][200])
            assert w["pv"][300] == pytest.approx(53.0)
            assert w.coverage == pytest.approx((n - 31) / n)
            assert np.isnan(w["mv"]).all() and "mv" not in w.signals
            raw = await store.read_samples(lp, T0 + 200_000_000, T0 + 201_000_000, signals=["pv"])
            assert raw == [("pv", T0 + 200_000_000, T0 + 200_000_000, None, BAD_SENSOR_FAILURE)]
            assert await store.latest_sample_us(lp) == T0 + (n - 1) * 1_000_000
            # retention keeps each tag's newest sample before the cutoff (299 s), deletes the rest
            assert await store.purge(T0 + 300 * 1_000_000) == 2 * 299 + 269  # PV: 30-s gap
            w2 = await store.read_window(lp, T0, T0 + n * 1_000_000, sample_time_s=1.0)
            assert np.isnan(w2["op"][:299]).all() and np.isfinite(w2["op"][299:]).all()
            await store.checkpoint()
        finally:
            await store.close()

    asyncio.run(body())


def test_retention_keeps_the_value_a_constant_signal_holds(db_url: str) -> None:
    """An OPC UA set point reported once, weeks before the retention cutoff, is still the
    window's SP after the purge; every other tag keeps its newest sample before the cutoff."""

    async def body() -> None:
        store = await Store.open(db_url)
        try:
            lp = (await store.sync_config(one_loop_config()))["FIC1"]
            day = 86_400_000_000
            rows = [Sample(lp.tags["sp"], T0, T0, 42.0, GOOD)]  # constant since, never resent
            for k in range(40):  # PV and OP every day for 40 days
                ts = T0 + k * day
                rows += [Sample(lp.tags[s], ts, ts, float(k), GOOD) for s in ("pv", "op")]
            await store.write_samples(rows)
            cutoff = T0 + 30 * day
            assert await store.purge(cutoff) == 2 * 29
            assert await store.purge(cutoff) == 0  # nothing more until newer samples age
            w = await store.read_window(lp, T0 + 35 * day, T0 + 40 * day, sample_time_s=86_400)
            assert w["sp"].tolist() == [42.0] * 5
            assert await store.last_before(lp, cutoff, ["pv"]) == {"pv": 29.0}
        finally:
            await store.close()

    asyncio.run(body())


def test_unmigrated_database_is_refused_with_the_fix(tmp_path: Path) -> None:
    async def body() -> None:
        with pytest.raises(StorageError, match=r"run `plantcheck db upgrade --config x.toml`"):
            await Store.open(f"sqlite+aiosqlite:///{tmp_path / 'new.db'}", config_hint="x.toml")

    asyncio.run(body())


def test_db_upgrade_and_import_cli(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    cfg = tmp_path / "plantcheck.toml"
    cfg.write_text(f'[storage]\nurl = "sqlite+aiosqlite:///{tmp_path / "p.db"}"\n')
    rec = tmp_path / "r.csv"
    rec.write_text(
        "timestamp,sp,pv,op\n2026-01-01T00:00:00Z,50,49.5,40\n2026-01-01T00:00:01Z,50,,41\n"
        "2026-01-01T00:00:02Z,50,50.2,42\n"
    )
    r = run_cli("import", str(rec), "--loop", "L1", "--config", str(cfg))
    assert r.returncode == 2 and f"plantcheck db upgrade --config {cfg}`" in r.stderr, r.stderr
    assert not (tmp_path / "p.db").exists()  # a refused import leaves no empty database
    # the ids the configuration would refuse are refused here too, before anything is read
    for bad_id in ("L 1", "FIC/101", "x" * 65, ""):
        r = run_cli("import", str(rec), "--loop", bad_id, "--config", str(cfg))
        assert r.returncode == 2 and "--loop: loop id" in r.stderr, (bad_id, r.stderr)
    r = run_cli("import", str(rec), "--loop", "L1", "--loop-type", "valve", "--config", str(cfg))
    assert r.returncode == 2 and "--loop-type" in r.stderr
    assert run_cli("db", "upgrade", "--config", str(cfg)).returncode == 0
    r = run_cli("import", str(rec), "--loop", "L1", "--config", str(cfg))
    assert r.returncode == 0, r.stderr
    assert "9 samples of loop L1 (3 time points), 9 new, 0 already stored" in r.stdout
    r = run_cli("import", str(rec), "--loop", "L1", "--config", str(cfg))
    assert r.returncode == 0 and "0 new, 9 already stored" in r.stdout, r.stdout

    async def check() -> None:
        store = await Store.open(f"sqlite+aiosqlite:///{tmp_path / 'p.db'}")
        try:
            assert await store.count_samples() == 9  # imported twice, stored once
            lp = (await store.loops())["L1"]
            rows = await store.read_samples(lp, signals=["pv"])
            assert [r[3] for r in rows] == [49.5, None, 50.2]
        finally:
            await store.close()

    asyncio.run(check())
    bad = tmp_path / "bad.toml"
    bad.write_text('[storage]\nurl = "mysql://x"\n')
    r = run_cli("db", "upgrade", "--config", str(bad))
    assert r.returncode == 2 and f"{bad}:2: storage.url" in r.stderr


def test_upgrade_clusters_an_existing_sqlite_samples_table(tmp_path: Path) -> None:
    """Migration 0002 rebuilds a rowid samples table (made before it) and keeps every row."""
    import sqlite3

    from alembic import command

    from plantcheck.storage.database import alembic_config, upgrade

    path = tmp_path / "old.db"
    url = f"sqlite+aiosqlite:///{path}"
    upgrade(url)
    command.downgrade(alembic_config(url), "0001")  # the samples table as 0001 first made it
    con = sqlite3.connect(path)
    sql = con.execute("SELECT sql FROM sqlite_master WHERE name = 'samples'").fetchone()[0]
    assert "WITHOUT ROWID" not in sql.upper()
    rows = [(k % 3 + 1, T0 + k, T0 + k, float(k), 0) for k in range(1000)]
    con.executemany("INSERT INTO samples VALUES (?, ?, ?, ?, ?)", rows)
    con.commit()
    con.close()
    upgrade(url)
    con = sqlite3.connect(path)
    sql = con.execute("SELECT sql FROM sqlite_master WHERE name = 'samples'").fetchone()[0]
    assert "WITHOUT ROWID" in sql.upper()
    got = con.execute("SELECT * FROM samples ORDER BY ts_us").fetchall()
    con.close()
    assert got == rows


def test_window_reads_recover_after_the_connection_is_lost(db_url: str) -> None:
    """The scheduler's window reads share one kept connection: when PostgreSQL drops it the
    read is retried on a fresh one; a failed statement does not break the reads after it."""

    async def body() -> None:
        store = await Store.open(db_url)
        try:
            lp = (await store.sync_config(one_loop_config()))["FIC1"]
            await store.write_samples(
                [Sample(lp.tags["pv"], T0 + k, T0 + k, float(k), GOOD) for k in range(100)]
            )
            before = await store.read_series(lp, T0, T0 + 100, kept=True)
            if store.dialect == "postgresql":
                import asyncpg

                url = db_url.replace("postgresql+asyncpg", "postgresql")
                admin = await asyncpg.connect(url)
                try:
                    await admin.execute(
                        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                        "WHERE datname = current_database() AND pid <> pg_backend_pid()"
                    )
                finally:
                    await admin.close()
                again = await store.read_series(lp, T0, T0 + 100, kept=True)
                assert np.array_equal(again["pv"][1], before["pv"][1])
            else:
                with pytest.raises(Exception):  # noqa: B017 - sqlite3's error
                    await store._fetch("SELECT no_such_column FROM samples", kept=True)
            after = await store.read_series(lp, T0, T0 + 100, kept=True)
            assert np.array_equal(after["pv"][1], before["pv"][1])
            assert after["pv"][1].tolist() == [float(k) for k in range(100)]
        finally:
            await store.close()

    asyncio.run(body())


def test_migration_0007_gives_older_loops_their_area_and_indices(tmp_path: Path) -> None:
    """A database of 0006 keeps its loops and gains area, unit, criticality and kpis."""
    import sqlite3

    from alembic import command

    from plantcheck.storage.database import alembic_config, upgrade

    path = tmp_path / "old.db"
    url = f"sqlite+aiosqlite:///{path}"
    upgrade(url)
    command.downgrade(alembic_config(url), "0006")
    con = sqlite3.connect(path)
    assert "area" not in {r[1] for r in con.execute("PRAGMA table_info(loops)")}
    con.execute("INSERT INTO loops (name, type, source, description, state) "
                "VALUES ('FIC1', 'flow', 'plc', '', 'ok')")  # fmt: skip
    con.commit()
    con.close()
    upgrade(url)
    con = sqlite3.connect(path)
    got = con.execute("SELECT name, area, unit, criticality, kpis FROM loops").fetchall()
    con.close()
    assert got == [("FIC1", "", "", None, None)]
