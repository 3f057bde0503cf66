"""The plant at a glance: loops counted by state and by cause, per area, now and a week ago
(issue 49 item 2), what a morning meeting reads before it opens a loop.

"Now" is each loop's verdict (the loop table). "Then" is each loop's latest diagnosis whose
window ended at or before that time (the store keeps each diagnosis, not each past verdict); a
loop not diagnosed by then counts as ``unknown``. Loops with no area count for the plant only.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from sqlalchemy import func, select

from plantcheck.storage.schema import diagnoses, loops
from plantcheck.storage.store import Store

WEEK_US = 7 * 86_400 * 1_000_000


@dataclass
class Counts:
    """Loops by state and by cause."""

    loops: int = 0
    by_state: Counter[str] = field(default_factory=Counter)
    by_cause: Counter[str] = field(default_factory=Counter)

    def add(self, state: str, cause: str | None) -> None:
        self.loops += 1
        self.by_state[state] += 1
        if cause:
            self.by_cause[cause] += 1


@dataclass(frozen=True)
class AreaSummary:
    """One area's counts now, a week before, and the change (now − then) per state and cause."""

    area: str
    now: Counts
    then: Counts

    def change(self) -> tuple[dict[str, int], dict[str, int]]:
        """(per state, per cause) now − then, only what changed."""
        return _delta(self.now.by_state, self.then.by_state), _delta(
            self.now.by_cause, self.then.by_cause
        )


def _delta(now: Counter[str], then: Counter[str]) -> dict[str, int]:
    keys = sorted(set(now) | set(then))
    return {k: now[k] - then[k] for k in keys if now[k] != then[k]}


@dataclass(frozen=True)
class PlantSummary:
    """The whole plant (``plant``, area "") and each area, now (``at_us``) and at ``then_us``."""

    at_us: int
    then_us: int
    plant: AreaSummary
    areas: list[AreaSummary]


async def plant_summary(store: Store, now_us: int, span_us: int = WEEK_US) -> PlantSummary:
    """Counts by state and cause, for the plant and per area, now and ``span_us`` before."""
    then_us = now_us - span_us
    latest_then = (
        select(func.max(diagnoses.c.id))
        .where(diagnoses.c.window_end_us <= then_us)
        .group_by(diagnoses.c.loop_id)
    )
    now_q = select(loops.c.id, loops.c.area, loops.c.state, loops.c.cause)
    then_q = select(diagnoses.c.loop_id, diagnoses.c.state, diagnoses.c.cause).where(
        diagnoses.c.id.in_(latest_then.scalar_subquery())
    )
    async with store.engine.connect() as conn:
        rows = (await conn.execute(now_q)).all()
        past = {r.loop_id: (r.state, r.cause) for r in (await conn.execute(then_q)).all()}
    now: dict[str, Counts] = {}
    then: dict[str, Counts] = {}
    for r in rows:
        for area in ("", r.area) if r.area else ("",):
            now.setdefault(area, Counts()).add(r.state, r.cause)
            then.setdefault(area, Counts()).add(*past.get(r.id, ("unknown", None)))
    total = AreaSummary("", now.get("", Counts()), then.get("", Counts()))
    areas = [AreaSummary(a, now[a], then[a]) for a in sorted(now) if a]
    return PlantSummary(now_us, then_us, total, areas)
