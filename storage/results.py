"""Diagnosis results in the store: write one verdict, read the tables the API serves.

A loop's state, cause and ``since`` change only when the verdict (its cause) changes; the
suggested action of the previous verdict is then closed and the new one opened. Times are µs
since 1970-01-01 UTC, as everywhere in the store.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from sqlalchemy import bindparam, func, insert, select, update
from sqlalchemy.ext.asyncio import AsyncConnection
from sqlalchemy.sql.elements import ColumnElement

from plantcheck.diagnosis.priority import loop_priority
from plantcheck.storage.alerts import AlertDraft, enqueue_alerts
from plantcheck.storage.schema import actions, diagnoses, loops, stiction_estimates
from plantcheck.storage.store import LoopRow, Store
from plantcheck.storage.trends import (
    ESTIMATE_COLUMNS,
    METHOD_RANK,
    StoredEstimate,
    refresh_trends,
)


@dataclass(frozen=True)
class Verdict:
    """What the scheduler stores for one diagnosed window."""

    loop: LoopRow
    created_us: int
    window_start_us: int
    window_end_us: int
    cause: str
    state: str
    payload: dict[str, Any]
    action_code: str
    action_text: str
    priority: int
    S: float | None = None
    J: float | None = None
    stiction_source: str = "op_pv"
    stiction_method: str = "hammerstein"
    """How S was estimated: ``hammerstein``, ``events``, ``ellipse`` (contracts §2) or
    ``measured`` (from the stem position)."""
    stiction_reliable: bool = True
    stiction_limit: float = 2.0
    """The valve's S limit (% of travel) its trend is projected to (the loop's setting)."""


@dataclass(frozen=True)
class LoopStatus:
    """A row of the loop-health table."""

    id: str
    type: str
    source: str
    description: str
    state: str
    cause: str | None
    since_us: int | None
    last_diagnosis_us: int | None
    S: float | None
    J: float | None
    S_method: str | None = None
    S_at_us: int | None = None
    """When S and J were estimated (µs UTC, the end of the window they came from)."""
    area: str = ""
    unit: str = ""
    criticality: int | None = None
    kpis: dict[str, Any] | None = None
    """The indices of the latest diagnosis (contracts §2 ``kpis``)."""
    priority: float = 0.0
    """How urgently the loop needs attention, 0-100 (``diagnosis.priority``)."""


QUANTIFIED_CAUSES = frozenset({"stiction", "deadband_backlash"})
"""Causes whose diagnosis carries an S (and J) estimate (the stiction report), and whose action
text then names it."""


@dataclass(frozen=True)
class PendingVerdict:
    """A verdict to store: with ``adopt`` (or when the loop has none yet) a new cause becomes
    the loop's verdict from ``since_us`` (default: the verdict's ``created_us``)."""

    verdict: Verdict
    adopt: bool = True
    since_us: int | None = None
    alerts: tuple[AlertDraft, ...] = ()
    """Alerts to store with the verdict if it changes (``storage.alerts``)."""


async def record_verdict(
    store: Store, v: Verdict, adopt: bool = True, since_us: int | None = None
) -> bool:
    """Store one diagnosis (see ``record_verdicts``); returns whether the loop's verdict
    changed."""
    return (await record_verdicts(store, [PendingVerdict(v, adopt, since_us)]))[0]


async def record_verdicts(store: Store, batch: Sequence[PendingVerdict]) -> list[bool]:
    """Store diagnoses of distinct loops in one transaction, a few statements for the whole
    batch: each diagnosis in the history, the loop's last diagnosis time, a new verdict (state,
    cause, ``since``; the previous action closed, the new one opened) where the cause changed
    and is adopted, the current action's text refreshed otherwise, and the S/J estimates.
    Returns, per item, whether the loop's verdict changed."""
    ids = [p.verdict.loop.id for p in batch]
    assert len(set(ids)) == len(ids), "one verdict per loop in a batch"
    if not batch:
        return []
    async with store.engine.begin() as conn:
        found = await conn.execute(select(loops.c.id, loops.c.cause).where(loops.c.id.in_(ids)))
        cur = {r[0]: r[1] for r in found.all()}
        changed = [
            cur.get(p.verdict.loop.id) != p.verdict.cause
            and (p.adopt or cur.get(p.verdict.loop.id) is None)
            for p in batch
        ]
        await conn.execute(
            insert(diagnoses),
            [
                {
                    "loop_id": v.loop.id,
                    "created_us": v.created_us,
                    "window_start_us": v.window_start_us,
                    "window_end_us": v.window_end_us,
                    "cause": v.cause,
                    "state": v.state,
                    "payload": v.payload,
                }
                for v in (p.verdict for p in batch)
            ],
        )
        new = [p for p, c in zip(batch, changed, strict=True) if c]
        same = [p.verdict for p, c in zip(batch, changed, strict=True) if not c]
        if same:
            await conn.execute(
                update(loops)
                .where(loops.c.id == bindparam("b_id"))
                .values(last_diagnosis_us=bindparam("b_at"), kpis=bindparam("b_kpis")),
                [
                    {"b_id": v.loop.id, "b_at": v.created_us, "b_kpis": v.payload.get("kpis")}
                    for v in same
                ],
            )
            # same verdict: keep the action and its ``since``, refresh its text when it brings
            # news (a new S); a window not quantified keeps the numbers the text already has,
            # so every page shows one text with the numbers known (issue 47)
            news = [v for v in same if v.S is not None or v.cause not in QUANTIFIED_CAUSES]
            if news:
                await conn.execute(
                    update(actions)
                    .where(
                        actions.c.loop_id == bindparam("b_id"),
                        actions.c.active.is_(True),
                        actions.c.cause == bindparam("b_cause"),
                    )
                    .values(text=bindparam("b_text")),
                    [
                        {"b_id": v.loop.id, "b_cause": v.cause, "b_text": v.action_text}
                        for v in news
                    ],
                )
        if new:
            await _adopt(conn, new)
            for p in new:
                if p.alerts:
                    before = cur.get(p.verdict.loop.id)
                    drafts = [replace(d, payload={**d.payload, "previous_cause": before})
                              for d in p.alerts]  # fmt: skip
                    await enqueue_alerts(conn, p.verdict.loop.id, p.verdict.created_us, drafts)
        estimates = [p.verdict for p in batch if p.verdict.S is not None]
        if estimates:
            await conn.execute(
                insert(stiction_estimates),
                [
                    {
                        "loop_id": v.loop.id,
                        "at_us": v.window_end_us,
                        "S": v.S,
                        "J": v.J,
                        "source": v.stiction_source,
                        "method": v.stiction_method,
                        "reliable": v.stiction_reliable,
                    }
                    for v in estimates
                ],
            )
            now_us = max(v.created_us for v in estimates)
            await refresh_trends(conn, [(v.loop.id, v.stiction_limit) for v in estimates], now_us)
    return changed


async def _adopt(conn: AsyncConnection, batch: Sequence[PendingVerdict]) -> None:
    """New verdicts: the loop's state, cause and ``since``; its active action closed and the
    new one (if any) opened."""
    await conn.execute(
        update(loops)
        .where(loops.c.id == bindparam("b_id"))
        .values(
            last_diagnosis_us=bindparam("b_at"),
            state=bindparam("b_state"),
            cause=bindparam("b_cause"),
            since_us=bindparam("b_since"),
            kpis=bindparam("b_kpis"),
        ),
        [
            {
                "b_id": p.verdict.loop.id,
                "b_at": p.verdict.created_us,
                "b_kpis": p.verdict.payload.get("kpis"),
                "b_state": p.verdict.state,
                "b_cause": p.verdict.cause,
                "b_since": p.since_us or p.verdict.created_us,
            }
            for p in batch
        ],
    )
    await conn.execute(
        update(actions)
        .where(actions.c.loop_id == bindparam("b_id"), actions.c.active.is_(True))
        .values(active=False, closed_us=bindparam("b_at")),
        [{"b_id": p.verdict.loop.id, "b_at": p.verdict.created_us} for p in batch],
    )
    opened = [p for p in batch if p.verdict.action_code != "none"]
    if opened:
        await conn.execute(
            insert(actions),
            [
                {
                    "loop_id": p.verdict.loop.id,
                    "cause": p.verdict.cause,
                    "code": p.verdict.action_code,
                    "text": p.verdict.action_text,
                    "priority": p.verdict.priority,
                    # the loop's since: one change, one time on every page (issue 47)
                    "since_us": p.since_us or p.verdict.created_us,
                    "active": True,
                }
                for p in opened
            ],
        )


async def loop_statuses(
    store: Store, name: str | None = None, diagnosed_since_us: int | None = None
) -> list[LoopStatus]:
    """The loop-health table (one loop with ``name``; the loops diagnosed at or after
    ``diagnosed_since_us``, for a table kept up to date by increments), with each valve's
    latest reliable S and J of the most direct method it has (``METHOD_RANK``): a valve
    quantified by identification now and then keeps that S between identifications rather than
    flipping to another method's.
    """
    q = select(loops).order_by(loops.c.name)
    latest = (
        select(func.max(stiction_estimates.c.id))
        .where(stiction_estimates.c.reliable.is_(True))
        .group_by(stiction_estimates.c.loop_id, stiction_estimates.c.method)
    )
    subset = None
    if name is not None:
        subset = loops.c.name == name
    elif diagnosed_since_us is not None:
        subset = loops.c.last_diagnosis_us >= diagnosed_since_us
    if subset is not None:
        q = q.where(subset)
        latest = latest.where(stiction_estimates.c.loop_id.in_(select(loops.c.id).where(subset)))
    est_q = select(
        stiction_estimates.c.loop_id,
        stiction_estimates.c.S,
        stiction_estimates.c.J,
        stiction_estimates.c.method,
        stiction_estimates.c.at_us,
    ).where(stiction_estimates.c.id.in_(latest.scalar_subquery()))
    est: dict[int, tuple[float | None, float | None, str | None, int | None]] = {}
    async with store.engine.connect() as conn:
        rows = (await conn.execute(q)).all()
        for loop_id, S, J, method, at_us in (await conn.execute(est_q)).all():
            have = est.get(loop_id)
            if have is None or _rank(method) < _rank(have[2]):
                est[loop_id] = (S, J, method, at_us)
    none: tuple[float | None, float | None, str | None, int | None] = (None, None, None, None)
    return [
        LoopStatus(
            r.name,
            r.type,
            r.source,
            r.description,
            r.state,
            r.cause,
            r.since_us,
            r.last_diagnosis_us,
            *est.get(r.id, none),
            area=r.area,
            unit=r.unit,
            criticality=r.criticality,
            kpis=r.kpis,
            priority=loop_priority(r.state, r.criticality, r.kpis),
        )
        for r in rows
    ]


def _rank(method: str | None) -> int:
    return METHOD_RANK.index(method) if method in METHOD_RANK else len(METHOD_RANK)


def _between(col: Any, start_us: int | None, end_us: int | None) -> list[ColumnElement[bool]]:
    cond: list[ColumnElement[bool]] = []
    if start_us is not None:
        cond.append(col >= start_us)
    if end_us is not None:
        cond.append(col < end_us)
    return cond


async def diagnosis_history(
    store: Store,
    loop: LoopRow,
    start_us: int | None = None,
    end_us: int | None = None,
    limit: int = 100,
    offset: int = 0,
) -> tuple[int, list[dict[str, Any]]]:
    """(total, page) of a loop's diagnoses whose window ends in [start, end), newest first;
    each item has ``created_us``, ``window_start_us``, ``window_end_us`` and ``payload``."""
    cond = [diagnoses.c.loop_id == loop.id, *_between(diagnoses.c.window_end_us, start_us, end_us)]
    q = (
        select(diagnoses)
        .where(*cond)
        .order_by(diagnoses.c.window_end_us.desc(), diagnoses.c.id.desc())
        .limit(limit)
        .offset(offset)
    )
    async with store.engine.connect() as conn:
        total = int(
            (
                await conn.execute(select(func.count()).select_from(diagnoses).where(*cond))
            ).scalar_one()
        )
        rows = (await conn.execute(q)).all()
    return total, [r._asdict() for r in rows]


async def healthy_error_sd(
    store: Store, loop: LoopRow, since_us: int, limit: int = 500
) -> list[float]:
    """The control error's σ (``indices.error_std``) of the loop's ``ok`` diagnoses whose
    window ends after ``since_us``, newest first, at most ``limit``: the loop's own normal
    (issue 46 item 5)."""
    q = (
        select(diagnoses.c.payload)
        .where(
            diagnoses.c.loop_id == loop.id,
            diagnoses.c.cause == "ok",
            diagnoses.c.window_end_us >= since_us,
        )
        .order_by(diagnoses.c.window_end_us.desc())
        .limit(limit)
    )
    async with store.engine.connect() as conn:
        rows = (await conn.execute(q)).all()
    out = []
    for (payload,) in rows:
        sd = ((payload or {}).get("indices") or {}).get("error_std")
        if isinstance(sd, (int, float)) and sd > 0:
            out.append(float(sd))
    return out


async def active_actions(store: Store) -> list[dict[str, Any]]:
    """The suggested-action table: active actions by priority, then oldest first."""
    q = (
        select(actions, loops.c.name.label("loop"))
        .join(loops, loops.c.id == actions.c.loop_id)
        .where(actions.c.active.is_(True))
        .order_by(actions.c.priority, actions.c.since_us, loops.c.name)
    )
    async with store.engine.connect() as conn:
        return [r._asdict() for r in (await conn.execute(q)).all()]


async def count_estimates(
    store: Store, start_us: int | None = None, end_us: int | None = None
) -> int:
    """Stiction estimates stored in [start, end) (what a report over that span would read)."""
    q = (
        select(func.count())
        .select_from(stiction_estimates)
        .where(*_between(stiction_estimates.c.at_us, start_us, end_us))
    )
    async with store.engine.connect() as conn:
        return int((await conn.execute(q)).scalar_one())


async def stiction_history(
    store: Store, start_us: int | None = None, end_us: int | None = None
) -> dict[str, list[StoredEstimate]]:
    """Per loop name: its stiction estimates, oldest first."""
    q = (
        select(loops.c.name, *ESTIMATE_COLUMNS)
        .join(loops, loops.c.id == stiction_estimates.c.loop_id)
        .where(*_between(stiction_estimates.c.at_us, start_us, end_us))
        .order_by(loops.c.name, stiction_estimates.c.at_us)
    )
    out: dict[str, list[StoredEstimate]] = {}
    async with store.engine.connect() as conn:
        for r in (await conn.execute(q)).all():
            est = StoredEstimate.of(r)
            out.setdefault(r.name, []).append(est)
    return out


async def loop_states(store: Store) -> dict[str, str]:
    """Every loop's current state, by loop id."""
    q = select(loops.c.name, loops.c.state)
    async with store.engine.connect() as conn:
        return {r[0]: r[1] for r in (await conn.execute(q)).all()}


@dataclass(frozen=True)
class LoopHistory:
    """What a diagnosis worker that has not seen a loop before needs of its past: the latest
    causes (newest first, with their creation times, µs) and when its newest reliable
    identified S was estimated (window end, µs; None when never)."""

    causes: list[tuple[str, int]]
    last_window_end_us: int | None
    last_identified_us: int | None


async def recent_history(store: Store, loop_ids: Sequence[int], n: int) -> dict[int, LoopHistory]:
    """Each loop's last ``n`` diagnoses and newest reliable identified S (issue 28: the
    diagnosis workers share the debouncing and the quantification schedule through the store,
    not through one process's memory). Two indexed queries for the whole batch."""
    if not loop_ids:
        return {}
    rank = (
        func.row_number()
        .over(
            partition_by=diagnoses.c.loop_id,
            order_by=(diagnoses.c.window_end_us.desc(), diagnoses.c.id.desc()),
        )
        .label("rank")
    )
    latest = (
        select(
            diagnoses.c.loop_id,
            diagnoses.c.cause,
            diagnoses.c.created_us,
            diagnoses.c.window_end_us,
            rank,
        )
        .where(diagnoses.c.loop_id.in_(loop_ids))
        .subquery()
    )
    q = select(latest).where(latest.c.rank <= n).order_by(latest.c.loop_id, latest.c.rank)
    est = (
        select(stiction_estimates.c.loop_id, func.max(stiction_estimates.c.at_us))
        .where(
            stiction_estimates.c.loop_id.in_(loop_ids),
            stiction_estimates.c.reliable.is_(True),
            stiction_estimates.c.method.in_(("hammerstein", "measured")),
        )
        .group_by(stiction_estimates.c.loop_id)
    )
    async with store.engine.connect() as conn:
        rows = (await conn.execute(q)).all()
        identified = {int(r[0]): int(r[1]) for r in (await conn.execute(est)).all()}
    causes: dict[int, list[tuple[str, int]]] = {i: [] for i in loop_ids}
    ends: dict[int, int] = {}
    for r in rows:
        causes[int(r.loop_id)].append((str(r.cause), int(r.created_us)))
        if r.rank == 1:
            ends[int(r.loop_id)] = int(r.window_end_us)
    return {i: LoopHistory(causes[i], ends.get(i), identified.get(i)) for i in loop_ids}
