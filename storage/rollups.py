"""Hourly roll-ups of the samples: the long trends that outlive the samples' retention.

Samples are kept ``retention_days`` (30 by default); a plant wants years of its loops' trends
(issue 28: PostgreSQL for years of data). TimescaleDB keeps such a summary itself as a
continuous aggregate; plantcheck keeps it in a plain table, ``sample_hours``, on every
database, so SQLite, plain PostgreSQL and PostgreSQL with TimescaleDB behave alike and the same
code is tested on each. One row per tag and hour holds the count, mean, lowest and highest of
the hour's Good values (Bad samples and gaps are left out; an hour without a Good value has no
row).

Every hour the ingest writer rolls up the complete hours of its own tags since each tag's last
roll-up, re-reading the ``lookback`` before it so that samples a collector's store-and-forward
buffer delivers late still count (later than that they are not rolled up again): one grouped
range scan of the (tag_id, ts_us) key per tag, upserted, so two processes rolling up the same
tag agree. Roll-ups older than ``rollup_retention_days`` (ten years by default) are deleted the
same way, a key range per tag.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from sqlalchemy import and_, delete, func, select, text

from plantcheck.core.status_codes import BAD
from plantcheck.storage.schema import sample_hours, samples
from plantcheck.storage.store import LoopRow, Store, signal_range

HOUR_US = 3_600_000_000
"""One hour in µs: roll-ups start on whole hours since 1970 (UTC)."""

DEFAULT_LOOKBACK_US = 2 * HOUR_US
"""Hours before a tag's last roll-up that are rolled up again (late samples)."""

TAGS_PER_TRANSACTION = 200
"""Tags rolled up in one transaction: short transactions on a site of 40,000 tags."""

_UPSERT = text(
    # ts_us >= 0: integer division is the floor; SQLite (>= 3.24) and PostgreSQL share the
    # upsert syntax, and the WHERE clause keeps SQLite's parser from reading ON as a join
    f"""
    INSERT INTO sample_hours (tag_id, hour_us, n, mean, low, high)
    SELECT tag_id, (ts_us / {HOUR_US}) * {HOUR_US}, count(*), avg(value), min(value), max(value)
    FROM samples
    WHERE tag_id = :tag AND ts_us >= :lo AND ts_us < :hi
      AND value IS NOT NULL AND status < {BAD}
    GROUP BY 1, 2
    ON CONFLICT (tag_id, hour_us) DO UPDATE SET
      n = excluded.n, mean = excluded.mean, low = excluded.low, high = excluded.high
    """
)


@dataclass(frozen=True)
class HourRow:
    """One hour of one signal: start (µs since 1970, UTC), count and mean, lowest and highest
    of its Good values (engineering units)."""

    signal: str
    hour_us: int
    n: int
    mean: float
    low: float
    high: float


async def roll_up(
    store: Store,
    until_us: int,
    tag_ids: Iterable[int] | None = None,
    lookback_us: int = DEFAULT_LOOKBACK_US,
) -> int:
    """Roll up every complete hour before ``until_us`` not rolled up yet (and the
    ``lookback_us`` before each tag's last roll-up) of ``tag_ids`` (None: every tag); returns
    the hour rows written."""
    end = until_us // HOUR_US * HOUR_US
    ids = list(tag_ids) if tag_ids is not None else await store.tag_ids()
    written = 0
    for i in range(0, len(ids), TAGS_PER_TRANSACTION):
        async with store.engine.begin() as conn:
            for tag in ids[i : i + TAGS_PER_TRANSACTION]:
                last = (
                    await conn.execute(
                        select(func.max(sample_hours.c.hour_us)).where(sample_hours.c.tag_id == tag)
                    )
                ).scalar()
                if last is None:
                    first = (
                        await conn.execute(
                            select(func.min(samples.c.ts_us)).where(samples.c.tag_id == tag)
                        )
                    ).scalar()
                    if first is None:
                        continue
                    start = int(first) // HOUR_US * HOUR_US
                else:
                    start = max(0, int(last) + HOUR_US - lookback_us)
                if start >= end:
                    continue
                res = await conn.execute(_UPSERT, {"tag": tag, "lo": start, "hi": end})
                written += max(int(res.rowcount or 0), 0)
    return written


async def purge_hours(store: Store, before_us: int, tag_ids: Iterable[int] | None = None) -> int:
    """Delete roll-ups of hours starting before ``before_us`` of ``tag_ids`` (None: every tag),
    a key range per tag."""
    ids = list(tag_ids) if tag_ids is not None else await store.tag_ids()
    deleted = 0
    async with store.engine.begin() as conn:
        for tag in ids:
            res = await conn.execute(
                delete(sample_hours).where(
                    sample_hours.c.tag_id == tag, sample_hours.c.hour_us < before_us
                )
            )
            deleted += int(res.rowcount or 0)
    return deleted


async def read_hours(
    store: Store,
    loop: LoopRow,
    start_us: int | None = None,
    end_us: int | None = None,
    limit: int | None = None,
    signals: Sequence[str] | None = None,
) -> list[HourRow]:
    """The loop's hourly roll-ups starting in [start, end), oldest first."""
    tag_sig, cond = signal_range(
        loop, signals, sample_hours.c.tag_id, sample_hours.c.hour_us, start_us, end_us
    )
    if not tag_sig:
        return []
    q = (
        select(sample_hours)
        .where(and_(*cond))
        .order_by(sample_hours.c.hour_us, sample_hours.c.tag_id)
    )
    if limit is not None:
        q = q.limit(limit)
    async with store.engine.connect() as conn:
        rows = (await conn.execute(q)).all()
    return [HourRow(tag_sig[r.tag_id], r.hour_us, r.n, r.mean, r.low, r.high) for r in rows]
