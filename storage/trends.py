"""Each valve's stiction trend, computed when an estimate is stored, read by the report.

The maintenance report (``GET /api/v1/reports/stiction``) shows, per valve, the robust trend
of S (Theil–Sen, ``diagnosis.stiction_trend``; Bacci di Capaci & Scali 2014), its current level
and the date it is projected to pass the valve's limit. They are computed here, in the same
transaction that stores a new estimate, over every estimate the valve has, from one method (a
Hammerstein S and an apparent stiction are not the same quantity): the API only reads them.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import Row, delete, insert, select
from sqlalchemy.ext.asyncio import AsyncConnection

from plantcheck.diagnosis.stiction_trend import TrendParams, stiction_trend
from plantcheck.storage.schema import loops, stiction_estimates, stiction_trends
from plantcheck.storage.store import Store

METHOD_RANK = ("measured", "hammerstein", "events", "ellipse")
"""Estimate methods, most direct first: the stem position measured, the Hammerstein
identification, the stick-slip events, the PV(OP) ellipse's apparent stiction."""


@dataclass(frozen=True)
class StoredEstimate:
    """One stored stiction estimate: time (µs), S and J (% of travel), where it came from
    (``op_pv`` or ``mv``), its method and whether it passed its method's rules."""

    at_us: int
    S: float
    J: float | None
    source: str
    method: str
    reliable: bool

    @classmethod
    def of(cls, r: Row[*tuple[Any, ...]]) -> StoredEstimate:
        """From a row of ``ESTIMATE_COLUMNS``."""
        return cls(r.at_us, r.S, r.J, r.source, r.method, bool(r.reliable))


ESTIMATE_COLUMNS = (
    stiction_estimates.c.at_us,
    stiction_estimates.c.S,
    stiction_estimates.c.J,
    stiction_estimates.c.source,
    stiction_estimates.c.method,
    stiction_estimates.c.reliable,
)
"""The columns a ``StoredEstimate`` is read from."""


@dataclass(frozen=True)
class StoredTrend:
    """A valve's trend as of its latest estimate: the method it is read from, S and J now
    (% of travel), slope (%/week), whether S is above the limit and when it is projected to
    pass it (µs), the number of reliable estimates of that method it used, and its note."""

    computed_us: int
    method: str | None
    limit: float
    current_S: float | None
    current_J: float | None
    slope_per_week: float | None
    above_limit: bool
    projected_crossing_us: int | None
    used: int
    note: str


def trend_method(rows: Sequence[StoredEstimate], min_estimates: int) -> str | None:
    """The method a valve's trend is read from: the most direct one with ``min_estimates``
    reliable estimates, else the most direct one with any reliable estimate, else the most
    direct one present (whose unreliable points then give no trend)."""
    present = [m for m in METHOD_RANK if any(r.method == m for r in rows)]
    for enough in (min_estimates, 1):
        for m in present:
            if sum(r.method == m and r.reliable for r in rows) >= enough:
                return m
    return present[0] if present else None


def valve_trend(rows: Sequence[StoredEstimate], limit: float, now_us: int) -> StoredTrend:
    """The trend of one valve's estimates (oldest first) against its ``limit`` (S, %)."""
    params = TrendParams(limit=limit)
    method = trend_method(rows, params.min_estimates)
    used = [r for r in rows if r.method == method]
    at = np.array([r.at_us for r in used], dtype=np.int64)
    S = np.array([r.S for r in used], dtype=np.float64)
    J = np.array([np.nan if r.J is None else r.J for r in used], dtype=np.float64)
    ok = np.array([r.reliable for r in used], dtype=bool)
    tr = stiction_trend(at / 1e6, S, J, ok, params)
    crossing = tr.projected_crossing_s
    return StoredTrend(
        computed_us=now_us,
        method=method,
        limit=limit,
        current_S=tr.current_S,
        current_J=tr.current_J,
        slope_per_week=tr.slope_per_week,
        above_limit=tr.above_limit,
        projected_crossing_us=int(crossing * 1e6) if crossing is not None else None,
        used=int(ok.sum()),
        note=tr.note,
    )


async def refresh_trends(
    conn: AsyncConnection, limits: Iterable[tuple[int, float]], now_us: int
) -> None:
    """Recompute and store the trend of each (loop id, limit) from all its estimates, in the
    caller's transaction (the one that stored the new estimates)."""
    for loop_id, limit in limits:
        q = (
            select(*ESTIMATE_COLUMNS)
            .where(stiction_estimates.c.loop_id == loop_id)
            .order_by(stiction_estimates.c.at_us)
        )
        rows = [StoredEstimate.of(r) for r in (await conn.execute(q)).all()]
        tr = valve_trend(rows, limit, now_us)
        await conn.execute(delete(stiction_trends).where(stiction_trends.c.loop_id == loop_id))
        await conn.execute(
            insert(stiction_trends).values(
                loop_id=loop_id,
                computed_us=tr.computed_us,
                method=tr.method,
                limit_s=tr.limit,
                current_s=tr.current_S,
                current_j=tr.current_J,
                slope_per_week=tr.slope_per_week,
                above_limit=tr.above_limit,
                projected_crossing_us=tr.projected_crossing_us,
                used=tr.used,
                note=tr.note,
            )
        )


async def read_trends(store: Store) -> dict[str, StoredTrend]:
    """Every valve's stored trend, by loop name."""
    q = select(stiction_trends, loops.c.name).join(loops, loops.c.id == stiction_trends.c.loop_id)
    async with store.engine.connect() as conn:
        return {
            r.name: StoredTrend(
                r.computed_us,
                r.method,
                r.limit_s,
                r.current_s,
                r.current_j,
                r.slope_per_week,
                bool(r.above_limit),
                r.projected_crossing_us,
                r.used,
                r.note,
            )
            for r in (await conn.execute(q)).all()
        }
