"""Every stored stiction estimate names its method (issue 24): the scheduler picks the best size
a diagnosis has, the store keeps the method (migration 0003 for older databases) and computes
each valve's trend from one method when it stores an estimate, and the report reads that trend
and lists the other methods apart."""

from __future__ import annotations

import asyncio
import csv
import io
import sqlite3
from dataclasses import replace
from pathlib import Path

from helpers import T0, verdict_of

from plantcheck.api.models import StictionReport
from plantcheck.api.reports import report_csv, valve_report
from plantcheck.service.config import Config
from plantcheck.service.scheduler import stored_estimate
from plantcheck.storage.database import upgrade
from plantcheck.storage.results import PendingVerdict, loop_statuses, stiction_history
from plantcheck.storage.store import Store
from plantcheck.storage.trends import StoredEstimate, read_trends, trend_method, valve_trend
from plantcheck.storage.verdict_writer import VerdictWriter

HOUR = 3_600_000_000
WEEK = 7 * 24 * HOUR


def test_stored_estimate_prefers_the_identified_size() -> None:
    hammerstein = {"stiction": {"S": 3.0, "J": 1.0, "estimate": {"method": "hammerstein"}}}
    assert stored_estimate(hammerstein) == (3.0, 1.0, "hammerstein", True)
    measured = {"stiction": {"S": 2.0, "J": 0.5}, "valve": {"state": "stiction"}}
    assert stored_estimate(measured) == (2.0, 0.5, "measured", True)
    events = {
        "stiction": {
            "S": None,
            "J": None,
            "estimate": {"S": 1.8, "J": None, "method": "events", "reliable": False},
        }
    }
    assert stored_estimate(events) == (1.8, None, "events", False)
    assert stored_estimate({"stiction": {"S": None}}) is None


def _row(at_us: int, S: float, method: str, reliable: bool = True) -> StoredEstimate:
    return StoredEstimate(at_us, S, None, "op_pv", method, reliable)


def test_trend_reads_one_method_and_lists_the_others() -> None:
    rows = [_row(T0 + k * WEEK, 1.0 + 0.1 * k, "hammerstein") for k in range(4)]
    rows += [_row(T0 + k * WEEK + HOUR, 9.0, "ellipse", False) for k in range(4)]
    rows += [_row(T0 + 5 * WEEK, 2.5, "events", True)]
    assert trend_method(rows, 3) == "hammerstein"
    rows.sort(key=lambda r: r.at_us)
    rep = valve_report("FV1", rows, valve_trend(rows, 2.0, T0 + 6 * WEEK), limit=2.0)
    assert rep.trend_method == "hammerstein"
    assert rep.current_S is not None and rep.current_S < 2.0  # the ellipse's 9 % is not S
    assert rep.slope_per_week is not None and rep.slope_per_week > 0
    assert "5 other estimates listed, not in the trend" in rep.note
    assert {e.method for e in rep.estimates} == {"hammerstein", "ellipse", "events"}
    assert sum(w.estimates for w in rep.weeks) == 4
    text = report_csv(StictionReport(generated_at="x", start=None, end=None, valves=[rep]))
    by_method = {r["method"]: r["reliable"] for r in csv.DictReader(io.StringIO(text))}
    assert by_method == {"hammerstein": "true", "ellipse": "false", "events": "true"}


def test_events_make_the_trend_when_nothing_better_exists() -> None:
    rows = [_row(T0 + k * WEEK, 2.0 + 0.2 * k, "events") for k in range(3)]
    rows.append(_row(T0 + 4 * WEEK, 3.0, "ellipse", False))
    assert trend_method(rows, 3) == "events"
    only_unreliable = [_row(T0, 4.0, "ellipse", False)]
    rep = valve_report("FV2", only_unreliable, valve_trend(only_unreliable, 2.0, T0), limit=2.0)
    assert rep.trend_method == "ellipse" and rep.current_S is None


def _config() -> Config:
    return Config.model_validate(
        {
            "source": [{"name": "s", "protocol": "opcua", "url": "opc.tcp://127.0.0.1:1/"}],
            "loop": [{"id": "L1", "source": "s", "pv": "ns=2;s=L1.PV", "op": "ns=2;s=L1.OP"}],
        }
    )


def test_store_keeps_the_method(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)

    async def body() -> list[StoredEstimate]:
        store = await Store.open(url)
        writer = VerdictWriter(store, linger_s=0.01)
        try:
            row = (await store.sync_config(_config()))["L1"]
            v = verdict_of(row, T0, "stiction", 3.0, 1.0)
            await writer.write(PendingVerdict(v))
            events = replace(
                verdict_of(row, T0 + HOUR, "stiction", 1.5, None),
                stiction_method="events",
                stiction_reliable=False,
            )
            await writer.write(PendingVerdict(events))
            newer = replace(
                verdict_of(row, T0 + 2 * HOUR, "stiction", 2.2, None),
                stiction_method="events",
                stiction_reliable=True,
            )
            await writer.write(PendingVerdict(newer))
            # the loop table keeps the identified S between identifications
            (status,) = await loop_statuses(store, "L1")
            assert (status.S, status.J, status.S_method) == (3.0, 1.0, "hammerstein")
            # the trend was stored with the estimates, from one method: the most direct one
            # with a reliable estimate (three are needed for a slope)
            trend = (await read_trends(store))["L1"]
            assert (trend.method, trend.current_S, trend.used) == ("hammerstein", 3.0, 1)
            assert trend.slope_per_week is None and "at least 3" in trend.note
            assert trend.computed_us == T0 + 2 * HOUR
            return (await stiction_history(store))["L1"]
        finally:
            await writer.close()
            await store.close()

    got = asyncio.run(body())
    assert [(e.S, e.method, e.reliable) for e in got] == [
        (3.0, "hammerstein", True),
        (1.5, "events", False),
        (2.2, "events", True),
    ]


def test_migration_names_the_method_of_older_estimates(tmp_path: Path) -> None:
    """A database from before revision 0003: its estimates were all reliable, Hammerstein or
    measured from the stem position (``source = 'mv'``)."""
    path = tmp_path / "old.db"
    url = f"sqlite+aiosqlite:///{path}"
    upgrade(url)
    con = sqlite3.connect(path)
    con.executescript(
        """
        ALTER TABLE stiction_estimates DROP COLUMN method;
        ALTER TABLE stiction_estimates DROP COLUMN reliable;
        UPDATE alembic_version SET version_num = '0002';
        INSERT INTO loops (name, type, source, description, state) VALUES
            ('L1', 'flow', 's', '', 'unknown');
        """
    )
    loop = con.execute("SELECT id FROM loops").fetchone()[0]
    con.executemany(
        "INSERT INTO stiction_estimates (loop_id, at_us, S, J, source) VALUES (?, ?, ?, ?, ?)",
        [(loop, 1, 3.0, 1.0, "op_pv"), (loop, 2, 2.0, None, "mv")],
    )
    con.commit()
    con.close()
    upgrade(url)
    con = sqlite3.connect(path)
    rows = con.execute("SELECT source, method, reliable FROM stiction_estimates ORDER BY at_us")
    assert rows.fetchall() == [("op_pv", "hammerstein", 1), ("mv", "measured", 1)]
    con.close()
