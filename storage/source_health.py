"""Source health in the store: reported by whoever reads a source, read by every service.

A collector (``plantcheck ingest --collector NAME``) at the plant and the service itself report
their sources' health every few seconds; ``plantcheck run`` shows the sources it does not read
from these reports, and a report that stops coming means the collector is gone (issue 28).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import delete, insert, select

from plantcheck.core.source_health import SourceHealth
from plantcheck.storage.schema import source_health
from plantcheck.storage.store import Store


@dataclass(frozen=True)
class ReportedHealth:
    """A stored report: the source's health, who reported it and when (µs)."""

    health: SourceHealth
    collector: str
    reported_us: int


async def report_health(
    store: Store, collector: str, sources: Sequence[SourceHealth], now_us: int
) -> None:
    """Replace the reports of ``sources`` (one transaction; the other sources' stay)."""
    if not sources:
        return
    async with store.engine.begin() as conn:
        await conn.execute(
            delete(source_health).where(source_health.c.name.in_([h.name for h in sources]))
        )
        await conn.execute(
            insert(source_health),
            [
                {
                    "name": h.name,
                    "collector": collector,
                    "protocol": h.protocol,
                    "state": h.state,
                    "since_us": h.since_us,
                    "last_good_sample_us": h.last_good_sample_us,
                    "failures": h.failures,
                    "last_error": h.last_error[:2000],
                    "reported_us": now_us,
                }
                for h in sources
            ],
        )


async def reported_health(store: Store) -> dict[str, ReportedHealth]:
    """Every source's last report, by source name."""
    async with store.engine.connect() as conn:
        rows = (await conn.execute(select(source_health))).all()
    return {
        r.name: ReportedHealth(
            SourceHealth(
                r.name,
                r.protocol,
                r.state,
                r.since_us,
                r.last_good_sample_us,
                r.failures,
                r.last_error,
            ),
            r.collector,
            r.reported_us,
        )
        for r in rows
    }
