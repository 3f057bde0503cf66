"""The alert outbox (issue 49 item 4): messages to write with a verdict change, then deliver.

An alert is stored in the transaction that changes the loop's verdict (``record_verdicts``),
so a change is never stored without its alerts nor alerted without being stored, and the
outbox outlives a restart. The dispatcher (``service/alerts.py``) takes the due ones, and marks
each delivered, due again later (with its error), or failed for good. Times in µs since the
epoch (UTC).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, insert, select, update
from sqlalchemy.ext.asyncio import AsyncConnection

from plantcheck.storage.schema import alerts, loops
from plantcheck.storage.store import Store

STATUSES = ("pending", "delivered", "failed")


@dataclass(frozen=True)
class AlertDraft:
    """An alert to store if its verdict changes: to ``target`` by ``rule``, unless the rule
    alerted the same target for the same loop less than ``quiet_us`` before."""

    rule: str
    target: str
    quiet_us: int
    payload: dict[str, Any]


@dataclass(frozen=True)
class StoredAlert:
    """An outbox row."""

    id: int
    loop: str
    key: str
    rule: str
    target: str
    state: str
    cause: str
    payload: dict[str, Any]
    status: str
    attempts: int
    created_us: int
    next_try_us: int
    delivered_us: int | None
    last_error: str


async def enqueue_alerts(
    conn: AsyncConnection, loop_id: int, created_us: int, drafts: Sequence[AlertDraft]
) -> int:
    """Store the drafts of one verdict change (in the caller's transaction), those in their
    rule's quiet period left out; returns how many were stored. The idempotency key names the
    loop, the change and the target: a receiver can drop a message it already has."""
    stored = 0
    for d in drafts:
        last = (
            await conn.execute(
                select(func.max(alerts.c.created_us)).where(
                    alerts.c.loop_id == loop_id,
                    alerts.c.rule == d.rule,
                    alerts.c.target == d.target,
                )
            )
        ).scalar()
        if last is not None and created_us - int(last) < d.quiet_us:
            continue
        key = f"{d.payload['loop']}/{created_us}/{d.rule}/{d.target}"
        await conn.execute(
            insert(alerts).values(
                loop_id=loop_id, key=key, rule=d.rule, target=d.target,
                state=d.payload["state"], cause=d.payload["cause"],
                payload={**d.payload, "key": key}, status="pending", attempts=0,
                created_us=created_us, next_try_us=created_us, last_error="",
            )
        )  # fmt: skip
        stored += 1
    return stored


def _row(r: Any) -> StoredAlert:
    return StoredAlert(
        r.id, r.name, r.key, r.rule, r.target, r.state, r.cause, dict(r.payload), r.status,
        r.attempts, r.created_us, r.next_try_us, r.delivered_us, r.last_error,
    )  # fmt: skip


def _select() -> Any:
    return select(alerts, loops.c.name).join(loops, loops.c.id == alerts.c.loop_id)


async def due_alerts(store: Store, now_us: int, limit: int = 100) -> list[StoredAlert]:
    """Pending alerts due by ``now_us``, oldest first."""
    q = (
        _select()
        .where(alerts.c.status == "pending", alerts.c.next_try_us <= now_us)
        .order_by(alerts.c.next_try_us, alerts.c.id)
        .limit(limit)
    )
    async with store.engine.connect() as conn:
        return [_row(r) for r in (await conn.execute(q)).all()]


async def mark_alert(
    store: Store,
    alert_id: int,
    status: str,
    attempts: int,
    *,
    next_try_us: int | None = None,
    delivered_us: int | None = None,
    error: str = "",
) -> None:
    """Record a delivery attempt's outcome."""
    values: dict[str, Any] = {"status": status, "attempts": attempts, "last_error": error[:2000]}
    if next_try_us is not None:
        values["next_try_us"] = next_try_us
    if delivered_us is not None:
        values["delivered_us"] = delivered_us
    async with store.engine.begin() as conn:
        await conn.execute(update(alerts).where(alerts.c.id == alert_id).values(**values))


async def list_alerts(
    store: Store,
    start_us: int | None = None,
    end_us: int | None = None,
    limit: int = 100,
    offset: int = 0,
) -> tuple[int, list[StoredAlert]]:
    """(total, page) of the alerts created in [start, end), newest first."""
    cond = []
    if start_us is not None:
        cond.append(alerts.c.created_us >= start_us)
    if end_us is not None:
        cond.append(alerts.c.created_us < end_us)
    q = _select().where(*cond).order_by(alerts.c.id.desc()).limit(limit).offset(offset)
    async with store.engine.connect() as conn:
        total = (await conn.execute(select(func.count()).select_from(alerts).where(*cond))).scalar()
        rows = [_row(r) for r in (await conn.execute(q)).all()]
    return int(total or 0), rows


async def alert_counts(store: Store) -> dict[str, int]:
    """Alerts in the outbox by status."""
    q = select(alerts.c.status, func.count()).group_by(alerts.c.status)
    async with store.engine.connect() as conn:
        got = {str(s): int(n) for s, n in (await conn.execute(q)).all()}
    return {s: got.get(s, 0) for s in STATUSES}
