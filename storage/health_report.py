"""The weekly loop-health report's reads (issue 49 item 5): per loop, how its diagnoses of a
period split between the states, the means of its indices then and over the period before,
and the actions opened and closed in it.

Everything is aggregated by the database (counts, and means of the ``kpis`` the diagnoses
carry, read with SQLAlchemy's JSON paths, the same on SQLite and PostgreSQL): a week of a
thousand loops diagnosed every ten minutes is a million diagnoses, none of which is read into
Python. The time in a state is the period's span times the share of its diagnoses in that
state: diagnoses come once per period, so a share of them is a share of the time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import Float, and_, func, or_, select

from plantcheck.storage.schema import actions, diagnoses, loops
from plantcheck.storage.store import Store

TRENDED = (
    "variability_ratio",
    "harris_index",
    "service_factor",
    "error_std",
    "op_travel_per_day",
    "op_reversals_per_day",
)
"""The indices (contracts §2 ``kpis``) whose means the report compares."""


@dataclass
class LoopPeriod:
    """One loop over the report's period."""

    loop: str
    area: str
    criticality: int | None
    state: str
    cause: str | None
    diagnoses: int = 0
    state_share: dict[str, float] = field(default_factory=dict)
    """Share of the period's diagnoses in each state (0-1)."""
    kpis: dict[str, float | None] = field(default_factory=dict)
    """Mean of each trended index over the period."""
    kpis_before: dict[str, float | None] = field(default_factory=dict)
    """The same over the period of equal length before."""
    opened: list[dict[str, Any]] = field(default_factory=list)
    closed: list[dict[str, Any]] = field(default_factory=list)


def _kpi(name: str) -> Any:
    return func.avg(diagnoses.c.payload[("kpis", name)].as_float()).cast(Float).label(name)


async def _means(conn: Any, start_us: int, end_us: int) -> dict[int, dict[str, float | None]]:
    q = (
        select(diagnoses.c.loop_id, *(_kpi(k) for k in TRENDED))
        .where(diagnoses.c.window_end_us >= start_us, diagnoses.c.window_end_us < end_us)
        .group_by(diagnoses.c.loop_id)
    )
    out: dict[int, dict[str, float | None]] = {}
    for r in (await conn.execute(q)).all():
        values = zip(TRENDED, r[1:], strict=True)
        out[r[0]] = {k: (None if v is None else round(float(v), 4)) for k, v in values}
    return out


async def loop_periods(store: Store, start_us: int, end_us: int) -> list[LoopPeriod]:
    """Every loop over [start, end), by loop id."""
    span = end_us - start_us
    counts_q = (
        select(diagnoses.c.loop_id, diagnoses.c.state, func.count())
        .where(diagnoses.c.window_end_us >= start_us, diagnoses.c.window_end_us < end_us)
        .group_by(diagnoses.c.loop_id, diagnoses.c.state)
    )
    acts_q = (
        select(actions.c.loop_id, actions.c.cause, actions.c.code, actions.c.text,
               actions.c.since_us, actions.c.closed_us)
        .where(or_(
            and_(actions.c.since_us >= start_us, actions.c.since_us < end_us),
            and_(actions.c.closed_us >= start_us, actions.c.closed_us < end_us),
        ))
        .order_by(actions.c.since_us)
    )  # fmt: skip
    async with store.engine.connect() as conn:
        rows = (await conn.execute(select(loops).order_by(loops.c.name))).all()
        counts = (await conn.execute(counts_q)).all()
        now = await _means(conn, start_us, end_us)
        before = await _means(conn, start_us - span, start_us)
        acts = (await conn.execute(acts_q)).all()
    periods = {r.id: LoopPeriod(r.name, r.area, r.criticality, r.state, r.cause) for r in rows}
    for loop_id, state, n in counts:
        p = periods.get(loop_id)
        if p is not None:
            p.diagnoses += int(n)
            p.state_share[state] = int(n)
    for p in periods.values():
        p.state_share = {s: round(n / p.diagnoses, 4) for s, n in sorted(p.state_share.items())}
    empty = dict.fromkeys(TRENDED)
    for loop_id, p in periods.items():
        p.kpis = now.get(loop_id, empty)
        p.kpis_before = before.get(loop_id, empty)
    for a in acts:
        p = periods.get(a.loop_id)
        if p is None:
            continue
        item = {"cause": a.cause, "code": a.code, "text": a.text}
        if start_us <= a.since_us < end_us:
            p.opened.append({**item, "at_us": a.since_us})
        if a.closed_us is not None and start_us <= a.closed_us < end_us:
            p.closed.append({**item, "at_us": a.closed_us})
    return list(periods.values())
