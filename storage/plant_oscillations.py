"""What the plant-wide oscillation pass reads and writes (issue 49 item 3): every loop's latest
diagnosis, and the groups each pass found (the latest ``KEEP`` passes are kept)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sqlalchemy import delete, func, insert, select

from plantcheck.storage.schema import diagnoses, loops, plant_oscillations
from plantcheck.storage.store import Store

KEEP = 100
"""Passes kept: the latest serves the API, the others show how the groups came about."""


@dataclass(frozen=True)
class LatestDiagnosis:
    """A loop's latest diagnosis: its window's end (µs, source time) and the payload."""

    loop: str
    window_end_us: int
    payload: dict[str, Any]


async def latest_diagnoses(store: Store) -> list[LatestDiagnosis]:
    """Every diagnosed loop's latest diagnosis, by loop name."""
    newest = select(func.max(diagnoses.c.id)).group_by(diagnoses.c.loop_id)
    q = (
        select(loops.c.name, diagnoses.c.window_end_us, diagnoses.c.payload)
        .join(loops, loops.c.id == diagnoses.c.loop_id)
        .where(diagnoses.c.id.in_(newest.scalar_subquery()))
        .order_by(loops.c.name)
    )
    async with store.engine.connect() as conn:
        rows = (await conn.execute(q)).all()
    return [LatestDiagnosis(r[0], int(r[1]), dict(r[2] or {})) for r in rows]


async def record_plant_oscillations(store: Store, at_us: int, groups: list[dict[str, Any]]) -> None:
    """Store one pass's groups; passes beyond the latest ``KEEP`` are dropped."""
    async with store.engine.begin() as conn:
        res = await conn.execute(insert(plant_oscillations).values(at_us=at_us, groups=groups))
        newest_id = int(res.inserted_primary_key[0])  # type: ignore[index]
        await conn.execute(
            delete(plant_oscillations).where(plant_oscillations.c.id <= newest_id - KEEP)
        )


async def latest_plant_oscillations(store: Store) -> tuple[int, list[dict[str, Any]]] | None:
    """(when, groups) of the latest pass, or None before the first."""
    q = (
        select(plant_oscillations.c.at_us, plant_oscillations.c.groups)
        .order_by(plant_oscillations.c.id.desc())
        .limit(1)
    )
    async with store.engine.connect() as conn:
        row = (await conn.execute(q)).first()
    return None if row is None else (int(row[0]), list(row[1]))
