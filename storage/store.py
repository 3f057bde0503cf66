"""The time-series store: samples in, aligned loop windows out (SQLAlchemy 2.1, async).

One class for both databases. Sample writes are idempotent on (tag, source timestamp):
SQLite ``INSERT OR IGNORE``; PostgreSQL ``COPY`` into a temporary table, then
``INSERT … SELECT … ON CONFLICT DO NOTHING`` (asyncpg's binary COPY is the fast path).
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import chain, islice
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import Delete, and_, bindparam, delete, func, insert, select, text, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.ext.asyncio import AsyncConnection, AsyncEngine
from sqlalchemy.sql.elements import ColumnElement

from plantcheck.core.samples import Sample
from plantcheck.storage.database import make_engine, require_migrated, sqlite_file
from plantcheck.storage.errors import StorageError
from plantcheck.storage.schema import loops, samples, sources, tags
from plantcheck.storage.window import HELD, LoopWindow, align

_COLUMNS = ("tag_id", "ts_us", "recv_us", "value", "status")


class SourceSettings(Protocol):
    """What the store keeps of a configured source."""

    @property
    def name(self) -> str: ...
    @property
    def protocol(self) -> str: ...
    @property
    def url(self) -> str: ...
    @property
    def host(self) -> str: ...
    @property
    def port(self) -> int: ...
    @property
    def device_id(self) -> int: ...


class LoopSettings(Protocol):
    """What the store keeps of a configured loop."""

    @property
    def id(self) -> str: ...
    @property
    def type(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def area(self) -> str: ...
    @property
    def unit(self) -> str: ...
    @property
    def criticality(self) -> int | None: ...
    def tags(self) -> dict[str, str]: ...


class PlantSettings(Protocol):
    """The sources and loops of a configuration: the store takes plain settings and knows
    nothing of the service's configuration file."""

    @property
    def source(self) -> Sequence[SourceSettings]: ...
    @property
    def loop(self) -> Sequence[LoopSettings]: ...


@dataclass(frozen=True)
class LoopRow:
    """A stored loop with its tag ids by signal."""

    id: int
    name: str
    type: str
    source: str
    tags: dict[str, int]


async def first_of_tags(
    conn: AsyncConnection,
    tag_ids: Sequence[int],
    tag_col: ColumnElement[int],
    time_col: ColumnElement[int],
    *,
    last: bool = False,
) -> dict[int, int | None]:
    """The first (or ``last``) time of each of ``tag_ids`` in the table of ``tag_col`` and
    ``time_col`` (None: the tag has no row), in one statement: a correlated subquery per tag,
    which SQLite and PostgreSQL both answer from the (tag_id, time) key without a scan."""
    edge = func.max(time_col) if last else func.min(time_col)
    q = select(tags.c.id, select(edge).where(tag_col == tags.c.id).scalar_subquery()).where(
        tags.c.id.in_(list(tag_ids))
    )
    return {int(t): (None if v is None else int(v)) for t, v in (await conn.execute(q)).all()}


async def delete_per_tag(
    conn: AsyncConnection,
    tag_ids: Sequence[int],
    tag_col: ColumnElement[int],
    time_col: ColumnElement[int],
    before_us: int,
    statement: Delete,
) -> int:
    """Run ``statement`` (a delete of one tag's key range, bound on ``tag``) for every tag of
    ``tag_ids`` with a row older than ``before_us``; returns the rows deleted.

    One look at every tag's oldest row first: most tags of an hourly slice have nothing to
    delete, and a statement per tag costs the ingest process CPU it needs for commits."""
    oldest = await first_of_tags(conn, tag_ids, tag_col, time_col)
    deleted = 0
    for tag in tag_ids:
        first = oldest.get(tag)
        if first is not None and first < before_us:
            res = await conn.execute(statement, {"tag": tag})
            deleted += int(res.rowcount or 0)
    return deleted


def signal_range(
    loop: LoopRow,
    signals: Sequence[str] | None,
    tag_col: ColumnElement[int],
    time_col: ColumnElement[int],
    start_us: int | None,
    end_us: int | None,
) -> tuple[dict[int, str], list[ColumnElement[bool]]]:
    """The loop's tags of ``signals`` (all when None), by tag id, and the conditions that
    select them over [start, end) of ``time_col`` (either end open when None)."""
    tag_sig = {tid: sig for sig, tid in loop.tags.items() if not signals or sig in signals}
    cond: list[ColumnElement[bool]] = [tag_col.in_(list(tag_sig))]
    if start_us is not None:
        cond.append(time_col >= start_us)
    if end_us is not None:
        cond.append(time_col < end_us)
    return tag_sig, cond


def missing_sqlite_file(url: str, config_hint: str = "") -> None:
    """``StorageError`` naming the fix when ``url`` is a SQLite file that does not exist."""
    db = sqlite_file(url)
    if db is not None and not db.exists():
        cfg = f" --config {config_hint}" if config_hint else ""
        raise StorageError(
            f"the database {db} does not exist: run `plantcheck db upgrade{cfg}` to create it"
        )


Cursor = tuple[int, int]
"""Keyset position of a page of rows ordered by (time, tag id): the last row's pair."""


class Store:
    """Async access to one database (``Store.open(url)``; ``close()`` when done)."""

    def __init__(self, engine: AsyncEngine) -> None:
        self.engine = engine
        self.dialect = engine.dialect.name
        self._reader: AsyncConnection | None = None
        """Connection kept checked out for ``_fetch`` (the scheduler's window reads)."""
        self._reader_lock = asyncio.Lock()

    @classmethod
    async def open(cls, url: str, *, check: bool = True, config_hint: str = "") -> Store:
        """Connect; with ``check``, refuse an unmigrated database (``StorageError``). A SQLite
        file that does not exist is refused before connecting, which would leave an empty one
        behind (issue 47: a failed ``import`` made one)."""
        if check:
            missing_sqlite_file(url, config_hint)
        store = cls(make_engine(url))
        if check:
            try:
                await require_migrated(store.engine, config_hint)
            except Exception:
                await store.close()
                raise
        return store

    async def close(self) -> None:
        async with self._reader_lock:
            await self._drop_reader()
        await self.engine.dispose()

    async def _drop_reader(self) -> None:
        reader, self._reader = self._reader, None
        if reader is not None:
            with contextlib.suppress(Exception):  # already broken: nothing left to release
                await reader.close()

    async def ping(self) -> bool:
        """Whether the database answers a trivial query."""
        try:
            async with self.engine.connect() as conn:
                await conn.execute(text("SELECT 1"))
            return True
        except Exception:
            return False

    async def storage_mode(self) -> str:
        """Which database and sample layout this store runs on, for the start-up log."""
        retention = "retention: hourly range deletes per tag; long trends: hourly roll-ups"
        if self.dialect != "postgresql":
            return f"SQLite (WAL); {retention}"
        async with self.engine.connect() as conn:
            version = (await conn.execute(text("SHOW server_version"))).scalar_one()
            tsdb = (
                await conn.execute(
                    text("SELECT extversion FROM pg_extension WHERE extname = 'timescaledb'")
                )
            ).scalar()
        layout = (
            f"samples a TimescaleDB {tsdb} hypertable of one-day chunks"
            if tsdb
            else "plain tables (TimescaleDB not installed)"
        )
        return f"PostgreSQL {version}, {layout}; {retention}"

    # -- configuration -------------------------------------------------------------------
    async def sync_config(self, cfg: PlantSettings) -> dict[str, LoopRow]:
        """Create or update sources, loops and their tag mapping from the configuration
        (the service's ``Config``; any object of that shape).

        Collectors, workers and the service may start together on one database and create the
        same rows at once: the loser of such a race (a unique violation) finds the rows there
        and runs again as an update."""
        for attempt in range(5):
            try:
                await self._sync_config(cfg)
                break
            except IntegrityError:
                if attempt == 4:
                    raise
                await asyncio.sleep(0.1 * (attempt + 1))
        return await self.loops()

    async def _sync_config(self, cfg: PlantSettings) -> None:
        async with self.engine.begin() as conn:
            for s in cfg.source:
                endpoint = s.url or f"{s.host}:{s.port}/{s.device_id}"
                row = (
                    await conn.execute(select(sources.c.id).where(sources.c.name == s.name))
                ).first()
                if row is None:
                    await conn.execute(
                        insert(sources).values(name=s.name, protocol=s.protocol, endpoint=endpoint)
                    )
                else:
                    await conn.execute(
                        update(sources)
                        .where(sources.c.id == row[0])
                        .values(protocol=s.protocol, endpoint=endpoint)
                    )
            for lp in cfg.loop:
                where = {"area": lp.area, "unit": lp.unit, "criticality": lp.criticality}
                await self._upsert_loop(
                    conn, lp.id, lp.type, lp.source, lp.description, lp.tags(), where=where
                )

    async def ensure_loop(
        self, name: str, loop_type: str = "other", source: str = "", signals: Sequence[str] = ()
    ) -> LoopRow:
        """The loop ``name`` with tags for ``signals`` (created when missing; for imports)."""
        async with self.engine.begin() as conn:
            await self._upsert_loop(
                conn, name, loop_type, source, "", {s: f"import:{s}" for s in signals}, keep=True
            )
        return (await self.loops())[name]

    async def _upsert_loop(
        self,
        conn: AsyncConnection,
        name: str,
        loop_type: str,
        source: str,
        description: str,
        tag_map: dict[str, str],
        keep: bool = False,
        where: dict[str, Any] | None = None,
    ) -> None:
        """Create or update a loop and its tags; ``where`` holds its ``area``, ``unit`` and
        ``criticality`` (configuration)."""
        values = {"type": loop_type, "source": source, "description": description, **(where or {})}
        row = (await conn.execute(select(loops.c.id).where(loops.c.name == name))).first()
        if row is None:
            res = await conn.execute(insert(loops).values(name=name, **values))
            loop_id = int(res.inserted_primary_key[0])  # type: ignore[index]
        else:
            loop_id = int(row[0])
            if not keep:
                await conn.execute(update(loops).where(loops.c.id == loop_id).values(**values))
        have = {
            r.signal: r
            for r in (await conn.execute(select(tags).where(tags.c.loop_id == loop_id))).all()
        }
        for sig, address in tag_map.items():
            if sig not in have:
                await conn.execute(
                    insert(tags).values(loop_id=loop_id, signal=sig, address=address)
                )
            elif have[sig].address != address and not keep:
                await conn.execute(
                    update(tags).where(tags.c.id == have[sig].id).values(address=address)
                )

    async def loops(self) -> dict[str, LoopRow]:
        """Every stored loop by name."""
        async with self.engine.connect() as conn:
            lrows = (await conn.execute(select(loops))).all()
            trows = (await conn.execute(select(tags))).all()
        by_loop: dict[int, dict[str, int]] = {}
        for t in trows:
            by_loop.setdefault(t.loop_id, {})[t.signal] = t.id
        return {
            r.name: LoopRow(r.id, r.name, r.type, r.source, by_loop.get(r.id, {})) for r in lrows
        }

    async def loop(self, name: str) -> LoopRow | None:
        """One stored loop by name (two index look-ups, whatever the plant's size)."""
        async with self.engine.connect() as conn:
            r = (await conn.execute(select(loops).where(loops.c.name == name))).first()
            if r is None:
                return None
            trows = (await conn.execute(select(tags).where(tags.c.loop_id == r.id))).all()
        return LoopRow(r.id, r.name, r.type, r.source, {t.signal: t.id for t in trows})

    # -- samples -------------------------------------------------------------------------
    async def write_samples(self, rows: Sequence[Sample]) -> None:
        """Store ``rows`` in one transaction; rows already stored (same tag and source
        timestamp) are left as they are, so a replay after an outage is harmless."""
        if not rows:
            return
        if self.dialect == "postgresql":
            await self._copy_samples(rows)
            return
        async with self.engine.begin() as conn:
            await conn.execute(
                insert(samples).prefix_with("OR IGNORE"),
                [dict(zip(_COLUMNS, r, strict=True)) for r in rows],
            )

    async def _copy_samples(self, rows: Sequence[Sample]) -> None:
        async with self.engine.connect() as conn:
            raw = await conn.get_raw_connection()
            apg: Any = raw.driver_connection
            async with apg.transaction():
                await apg.execute(
                    "CREATE TEMP TABLE IF NOT EXISTS samples_in "
                    "(LIKE samples INCLUDING DEFAULTS) ON COMMIT DELETE ROWS"
                )
                await apg.copy_records_to_table("samples_in", records=rows, columns=list(_COLUMNS))
                await apg.execute(
                    "INSERT INTO samples SELECT * FROM samples_in ON CONFLICT DO NOTHING"
                )

    async def count_samples(self, tag_ids: Sequence[int] | None = None) -> int:
        q = select(text("count(*)")).select_from(samples)
        if tag_ids is not None:
            q = q.where(samples.c.tag_id.in_(list(tag_ids)))
        async with self.engine.connect() as conn:
            return int((await conn.execute(q)).scalar_one())

    async def read_samples(
        self,
        loop: LoopRow,
        start_us: int | None = None,
        end_us: int | None = None,
        limit: int | None = None,
        signals: Sequence[str] | None = None,
        after: Cursor | None = None,
        skip: int = 0,
    ) -> list[tuple[str, int, int, float | None, int]]:
        """(signal, ts_us, recv_us, value, status) of a loop in [start, end), oldest first
        (ties by tag id); with ``limit``, one bounded page (``page``) after the keyset
        ``after`` = (ts_us, tag id) with ``skip`` rows left out."""
        tag_sig, cond = signal_range(
            loop, signals, samples.c.tag_id, samples.c.ts_us, start_us, end_us
        )
        if not tag_sig:
            return []
        if limit is None:
            q = select(samples).where(and_(*cond)).order_by(samples.c.ts_us, samples.c.tag_id)
            async with self.engine.connect() as conn:
                rows: Sequence[Any] = (await conn.execute(q)).all()
        else:
            rows = await self.page(
                "samples", "ts_us", "recv_us, value, status", list(tag_sig), start_us, end_us,
                limit, after, skip,
            )  # fmt: skip
        return [(tag_sig[r[0]], r[1], r[2], r[3], r[4]) for r in rows]

    async def page(
        self,
        table: str,
        time_col: str,
        columns: str,
        tag_ids: Sequence[int],
        start_us: int | None,
        end_us: int | None,
        limit: int,
        after: Cursor | None = None,
        skip: int = 0,
    ) -> list[Sequence[Any]]:
        """Rows (tag_id, time, ``columns``...) of ``table`` for ``tag_ids`` in [start, end),
        ordered by (time, tag id), after the keyset ``after``, ``skip`` rows left out, at most
        ``limit``: the API's pages (issue 45).

        Index range scans per tag, merged here; the work is bounded by the page whatever the
        span (one statement ordered by time over several tags would sort every row of the span
        to return the first few). Each tag is first asked for its share of the page; a tag
        whose share ran out before the page was complete is asked for more, so signals logged
        at one rate read about the page, and any mix at most the page per tag."""
        need = skip + limit
        lo = -(2**63) if start_us is None else start_us
        hi = 2**63 - 1 if end_us is None else end_us
        tags = sorted(tag_ids)
        got: dict[int, list[Sequence[Any]]] = {t: [] for t in tags}
        done: set[int] = set()
        ask = need // max(1, len(tags)) + 1
        pg = self.dialect == "postgresql"
        ph = ("$1", "$2", "$3", "$4") if pg else ("?",) * 4
        sql = (
            f"SELECT tag_id, {time_col}, {columns} FROM {table} WHERE tag_id = {ph[0]} AND "
            f"{time_col} {{op}} {ph[1]} AND {time_col} < {ph[2]} ORDER BY {time_col} "
            f"LIMIT {ph[3]}"
        )
        async with self.engine.connect() as conn:
            while True:
                for t in tags:
                    if t in done:
                        continue
                    rows = got[t]
                    if rows:  # continue after what this tag returned
                        op, since = ">", rows[-1][1]
                    elif after is not None:
                        # past (T, id): later times, and time T itself for tags after id
                        op, since = (">" if t <= after[1] else ">="), max(lo, after[0])
                    else:
                        op, since = ">=", lo
                    more = await self._run_raw(conn, sql.format(op=op), (t, since, hi, ask))
                    rows.extend(more)
                    if len(more) < ask:
                        done.add(t)
                # complete up to the earliest last key of a tag that may have more
                open_ends = [(got[t][-1][1], t) for t in tags if t not in done]
                bound = min(open_ends) if open_ends else None
                merged = heapq.merge(*got.values(), key=lambda r: (r[1], r[0]))
                page = [r for r in islice(merged, need) if bound is None or (r[1], r[0]) <= bound]
                if len(page) >= need or bound is None:
                    return page[skip:]
                ask = min(2 * ask, need)

    async def read_window(
        self,
        loop: LoopRow,
        start_us: int,
        end_us: int,
        sample_time_s: float | None = None,
        hold: tuple[str, ...] = HELD,
    ) -> LoopWindow:
        """The loop's SP/PV/OP/MV/mode over [start, end) on one time base with the coverage
        of good samples (Bad and missing samples are NaN; ``hold`` signals keep their last
        value)."""
        series = await self.read_series(loop, start_us, end_us)
        before = await self.last_before(loop, start_us, hold)
        return align(series, start_us, end_us, sample_time_s, before, hold)

    async def read_series(
        self, loop: LoopRow, start_us: int, end_us: int, *, kept: bool = False
    ) -> dict[str, tuple[NDArray[np.int64], NDArray[np.float64]]]:
        """Per signal: (source timestamps µs, values with NaN for Bad) in [start, end).

        The hot path of every scheduled diagnosis: one statement for all the loop's tags (one
        range scan each, in tag order) through the driver's own connection, rows straight into
        numpy (no ORM rows). Timestamps (µs since 1970, < 2**53) are exact as float64.
        ``kept``: on the connection kept for the scheduler's reads (see ``_fetch``).
        """
        out: dict[str, tuple[NDArray[np.int64], NDArray[np.float64]]] = {}
        if not loop.tags:
            return out
        cond, params = self._range_filter(loop, start_us, end_us)
        # SQLite has no NaN: Bad (NULL) comes back as +inf (9e999) there
        value = (
            "COALESCE(value, 'NaN'::float8)"
            if self.dialect == "postgresql"
            else "ifnull(value, 9e999)"
        )
        sql = f"SELECT tag_id, ts_us, {value} FROM samples WHERE {cond} ORDER BY tag_id, ts_us"
        rows = await self._fetch(sql, *params, kept=kept)
        if not rows:
            return out
        a = np.fromiter(chain.from_iterable(rows), np.float64, count=3 * len(rows))
        a = a.reshape(-1, 3)
        tag = a[:, 0].astype(np.int64)
        t = a[:, 1].astype(np.int64)
        v = np.where(np.isfinite(a[:, 2]), a[:, 2], np.nan)
        for sig, tag_id in loop.tags.items():
            lo, hi = np.searchsorted(tag, [tag_id, tag_id + 1])
            if hi > lo:
                out[sig] = (t[lo:hi], v[lo:hi])
        return out

    def _range_filter(self, loop: LoopRow, start_us: int, end_us: int) -> tuple[str, list[Any]]:
        """WHERE clause and parameters for the loop's tags over [start, end) (``$n`` parameters
        on PostgreSQL, ``?`` on SQLite)."""
        ids = sorted(loop.tags.values())
        if self.dialect == "postgresql":
            return "tag_id = ANY($1::int[]) AND ts_us >= $2 AND ts_us < $3", [ids, start_us, end_us]
        marks = ",".join("?" * len(ids))
        return f"tag_id IN ({marks}) AND ts_us >= ? AND ts_us < ?", [*ids, start_us, end_us]

    async def _fetch(self, sql: str, *params: Any, kept: bool = False) -> list[Sequence[Any]]:
        """Rows of one raw statement on the driver's connection (``$n`` parameters on
        PostgreSQL, ``?`` on SQLite): the scheduler's reads skip SQLAlchemy's row layer.

        With ``kept`` (the scheduler's window reads, one after another) the statements share
        one connection kept checked out: a pool checkout and its reset cost ~0.5 ms a read, a
        quarter of a window's tail read. Each runs on its own, outside any transaction, so it
        sees everything committed before it; one that fails on the kept connection (dropped by
        a database restart) is retried once on a fresh one, as the pool's pre-ping would have
        done. Other readers (the API) take a pooled connection and never queue behind them.
        """
        if not kept:
            async with self.engine.connect() as conn:
                return await self._run_raw(conn, sql, params)
        async with self._reader_lock:
            while True:
                fresh = self._reader is None
                try:
                    if self._reader is None:
                        self._reader = await self.engine.connect()
                    return await self._run_raw(self._reader, sql, params)
                except Exception:
                    await self._drop_reader()
                    if fresh:
                        raise
                except BaseException:  # cancelled: the connection may be mid-statement
                    await self._drop_reader()
                    raise

    async def _run_raw(
        self, conn: AsyncConnection, sql: str, params: tuple[Any, ...]
    ) -> list[Sequence[Any]]:
        raw = await conn.get_raw_connection()
        driver: Any = raw.driver_connection
        if self.dialect == "postgresql":
            return list(await driver.fetch(sql, *params))
        return list(await driver.execute_fetchall(sql, params))

    async def last_before(
        self, loop: LoopRow, at_us: int, signals: Sequence[str]
    ) -> dict[str, float]:
        """The last stored value of each of ``signals`` before ``at_us`` (NaN when Bad)."""
        out: dict[str, float] = {}
        async with self.engine.connect() as conn:
            for sig in signals:
                if sig not in loop.tags:
                    continue
                q = (
                    select(samples.c.value)
                    .where(samples.c.tag_id == loop.tags[sig], samples.c.ts_us < at_us)
                    .order_by(samples.c.ts_us.desc())
                    .limit(1)
                )
                row = (await conn.execute(q)).first()
                if row is not None:
                    out[sig] = np.nan if row[0] is None else float(row[0])
        return out

    async def newest_samples(self, tag_ids: Sequence[int]) -> dict[int, tuple[int, int]]:
        """Per tag, the source time (µs) and status of its newest stored sample."""
        if not tag_ids:
            return {}
        newest = (
            select(samples.c.tag_id, func.max(samples.c.ts_us).label("ts"))
            .where(samples.c.tag_id.in_(list(tag_ids)))
            .group_by(samples.c.tag_id)
            .subquery()
        )
        q = select(samples.c.tag_id, samples.c.ts_us, samples.c.status).join(
            newest, and_(samples.c.tag_id == newest.c.tag_id, samples.c.ts_us == newest.c.ts)
        )
        async with self.engine.connect() as conn:
            rows = (await conn.execute(q)).all()
        return {int(t): (int(ts), int(st)) for t, ts, st in rows}

    async def latest_sample_us(self, loop: LoopRow, signal: str | None = None) -> int | None:
        """Source timestamp of the loop's newest stored sample (of ``signal`` only, if given)."""
        span = await self.sample_span_us(loop, signal)
        return None if span is None else span[1]

    async def sample_span_us(
        self, loop: LoopRow, signal: str | None = None, *, kept: bool = False
    ) -> tuple[int, int] | None:
        """Source timestamps of the loop's oldest and newest stored samples (of ``signal``);
        ``kept`` as in ``read_series``."""
        if signal is None:
            ids = list(loop.tags.values())
        else:
            ids = [loop.tags[signal]] if signal in loop.tags else []
        if not ids:
            return None
        # min and max in separate subqueries: SQLite answers a lone min() or max() from the
        # (tag_id, ts_us) key in O(log n), but scans every row for both in one SELECT
        params: list[Any]
        if self.dialect == "postgresql":
            cond, params = "tag_id = ANY($1::int[])", [ids]
        else:
            cond, params = f"tag_id IN ({','.join('?' * len(ids))})", ids + ids
        sql = (
            f"SELECT (SELECT min(ts_us) FROM samples WHERE {cond}), "
            f"(SELECT max(ts_us) FROM samples WHERE {cond})"
        )
        lo, hi = (await self._fetch(sql, *params, kept=kept))[0]
        return None if hi is None else (int(lo), int(hi))

    async def count_series(
        self, loop: LoopRow, start_us: int, end_us: int, *, kept: bool = False
    ) -> dict[str, int]:
        """Stored samples per signal (Bad ones included) in [start, end); signals without any
        are left out. Counting reads no values: far cheaper than ``read_series``. ``kept`` as
        in ``read_series``."""
        if not loop.tags:
            return {}
        cond, params = self._range_filter(loop, start_us, end_us)
        sql = f"SELECT tag_id, count(*) FROM samples WHERE {cond} GROUP BY tag_id"
        counts = {int(t): int(n) for t, n in await self._fetch(sql, *params, kept=kept)}
        return {sig: counts[t] for sig, t in loop.tags.items() if t in counts}

    # -- housekeeping --------------------------------------------------------------------
    async def tag_ids(self) -> list[int]:
        """Every tag's id."""
        async with self.engine.connect() as conn:
            return list((await conn.execute(select(tags.c.id).order_by(tags.c.id))).scalars())

    async def purge(self, before_us: int, tag_ids: Sequence[int] | None = None) -> int:
        """Delete samples older than ``before_us`` (retention) of ``tag_ids`` (None: every
        tag) except each tag's newest one before it; returns how many were deleted.

        A source that reports only changes (OPC UA) stores a constant set point or mode, or a
        valve stuck for weeks, once: that sample is the value held ever since (``last_before``),
        and deleting it would leave the windows without SP or mode (a loop in manual mode would
        then be diagnosed as if automatic). Tags are never deleted (a loop's signal keeps its
        tag), so every stored sample belongs to one of them; each tag's purge is a range of the
        (tag_id, ts_us) key, never a scan of the table.
        """
        kept = samples.alias("kept")
        newest = (
            select(func.max(kept.c.ts_us))
            .where(kept.c.tag_id == bindparam("tag"), kept.c.ts_us < before_us)
            .scalar_subquery()
        )
        # NULL (no sample before the cutoff) deletes nothing
        older = delete(samples).where(
            samples.c.tag_id == bindparam("tag"), samples.c.ts_us < newest
        )
        ids = list(tag_ids) if tag_ids is not None else await self.tag_ids()
        async with self.engine.begin() as conn:
            return await delete_per_tag(
                conn, ids, samples.c.tag_id, samples.c.ts_us, before_us, older
            )

    async def checkpoint(self) -> None:
        """SQLite: fold the WAL back into the database file (no-op on PostgreSQL)."""
        if self.dialect != "sqlite":
            return
        async with self.engine.connect() as conn:
            await conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
