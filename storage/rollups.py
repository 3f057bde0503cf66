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
tag agree. One statement per slice of tags finds which of them have anything to do, so an hour
with nothing new costs a site no statement per tag. Roll-ups older than
``rollup_retention_days`` (ten years by default) are deleted the same way, a key range per tag.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import and_, bindparam, delete, select, text

from plantcheck.core.status_codes import BAD
from plantcheck.storage.schema import sample_hours, samples
from plantcheck.storage.store import (
    Cursor,
    LoopRow,
    Store,
    delete_per_tag,
    first_of_tags,
    signal_range,
)

HOUR_US = 3_600_000_000
"""One hour in µs: roll-ups start on whole hours since 1970 (UTC)."""

DEFAULT_LOOKBACK_US = 2 * HOUR_US
"""Hours before a tag's last roll-up that are rolled up again (late samples)."""

TAGS_PER_TRANSACTION = 200
"""Tags rolled up in one transaction: short transactions on a site of 40,000 tags."""

_UPSERT = text(
    # ts_us >= 0: integer division is the floor; SQLite (>= 3.24) and PostgreSQL share the
    # upsert syntax, and the WHERE clause keeps SQLite's parser from reading ON as a join.
    # A re-read hour only replaces its row when it counts at least as many values: late
    # samples only add to an hour, while retention (which keeps each tag's newest sample) can
    # leave one value of an hour still inside the lookback of a tag that stopped reporting,
    # and that remnant must not overwrite the hour's summary
    f"""
    INSERT INTO sample_hours (tag_id, hour_us, n, mean, low, high)
    SELECT tag_id, (ts_us / {HOUR_US}) * {HOUR_US}, count(*), avg(value), min(value), max(value)
    FROM samples
    WHERE tag_id = :tag AND ts_us >= :lo AND ts_us < :hi
      AND value IS NOT NULL AND status < {BAD}
    GROUP BY 1, 2
    ON CONFLICT (tag_id, hour_us) DO UPDATE SET
      n = excluded.n, mean = excluded.mean, low = excluded.low, high = excluded.high
    WHERE excluded.n >= sample_hours.n
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
        chunk = ids[i : i + TAGS_PER_TRANSACTION]
        async with store.engine.begin() as conn:
            # two statements find where each tag of the chunk stands, so a tag with nothing
            # new costs no statement of its own
            last_hour = await first_of_tags(
                conn, chunk, sample_hours.c.tag_id, sample_hours.c.hour_us, last=True
            )
            unrolled = [t for t in chunk if last_hour.get(t) is None]
            first = await first_of_tags(conn, unrolled, samples.c.tag_id, samples.c.ts_us)
            for tag in chunk:
                last = last_hour.get(tag)
                if last is not None:
                    start = max(0, last + HOUR_US - lookback_us)
                elif first.get(tag) is not None:
                    start = int(first[tag] or 0) // HOUR_US * HOUR_US
                else:
                    continue
                if start >= end:
                    continue
                res = await conn.execute(_UPSERT, {"tag": tag, "lo": start, "hi": end})
                written += max(int(res.rowcount or 0), 0)
    return written


async def purge_hours(store: Store, before_us: int, tag_ids: Iterable[int] | None = None) -> int:
    """Delete roll-ups of hours starting before ``before_us`` of ``tag_ids`` (None: every tag),
    a key range per tag."""
    ids = list(tag_ids) if tag_ids is not None else await store.tag_ids()
    older = delete(sample_hours).where(
        sample_hours.c.tag_id == bindparam("tag"), sample_hours.c.hour_us < before_us
    )
    async with store.engine.begin() as conn:
        return await delete_per_tag(
            conn, ids, sample_hours.c.tag_id, sample_hours.c.hour_us, before_us, older
        )


async def read_hours(
    store: Store,
    loop: LoopRow,
    start_us: int | None = None,
    end_us: int | None = None,
    limit: int | None = None,
    signals: Sequence[str] | None = None,
    after: Cursor | None = None,
    skip: int = 0,
) -> list[HourRow]:
    """The loop's hourly roll-ups starting in [start, end), oldest first (ties by tag id);
    with ``limit``, one bounded page after the keyset ``after`` = (hour_us, tag id)."""
    tag_sig, cond = signal_range(
        loop, signals, sample_hours.c.tag_id, sample_hours.c.hour_us, start_us, end_us
    )
    if not tag_sig:
        return []
    if limit is None:
        q = (
            select(sample_hours)
            .where(and_(*cond))
            .order_by(sample_hours.c.hour_us, sample_hours.c.tag_id)
        )
        async with store.engine.connect() as conn:
            rows: Sequence[Any] = (await conn.execute(q)).all()
    else:
        rows = await store.page(
            "sample_hours", "hour_us", "n, mean, low, high", list(tag_sig), start_us, end_us,
            limit, after, skip,
        )  # fmt: skip
    return [HourRow(tag_sig[r[0]], r[1], r[2], r[3], r[4], r[5]) for r in rows]
