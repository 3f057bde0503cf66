"""The ``/api/v1`` routes (contracts §5): loops, diagnoses, samples, actions, diagnose-now.

Lists are JSON arrays; pagination is ``limit``/``offset`` with the total in the
``X-Total-Count`` header and the next page in a ``Link: <...>; rel="next"`` header.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Sequence
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Path, Query, Request, Response

from plantcheck.api.deps import (
    Backend,
    TimeRange,
    get_loop,
    iso,
    iso_many,
    iso_required,
    require_read_key,
    require_write_key,
)
from plantcheck.api.loop_table import LoopSort, LoopTable, loop_json, select_loops
from plantcheck.api.models import (
    ActionOut,
    AlertOut,
    DiagnoseNow,
    DiagnosisOut,
    LoopDetail,
    LoopOut,
    SampleOut,
    SourceOut,
    State,
    StorageOut,
)
from plantcheck.core.names import NAME_PATTERN
from plantcheck.core.vocabulary import Cause, LoopType
from plantcheck.storage.alerts import list_alerts
from plantcheck.storage.results import (
    active_actions,
    diagnosis_history,
    loop_statuses,
)
from plantcheck.storage.rollups import read_hours
from plantcheck.storage.store import LoopRow, Store

router = APIRouter(prefix="/api/v1", dependencies=[Depends(require_read_key)])

LoopId = Annotated[
    str, Path(description="Loop id as configured, e.g. FIC101.", pattern=NAME_PATTERN)
]
Offset = Annotated[int, Query(ge=0, le=100_000, description="Items to skip (at most 100,000).")]
Responses = dict[int | str, dict[str, Any]]
NOT_FOUND: Responses = {404: {"description": "Unknown loop"}}
UNAUTHORIZED: Responses = {401: {"description": "Missing or wrong X-API-Key header"}}


def paginate(
    request: Request,
    response: Response,
    total: int | None,
    limit: int,
    offset: int,
    more: bool = False,
) -> None:
    """Set ``X-Total-Count`` (when known) and, when more items follow, a ``Link`` to the
    next page."""
    if total is not None:
        response.headers["X-Total-Count"] = str(total)
        more = offset + limit < total
    if more:
        # relative (RFC 8288 allows it): a URL built from the Host header would let any
        # client choose where the next-page link points
        nxt = request.url.include_query_params(offset=offset + limit, limit=limit)
        response.headers["Link"] = f'<{nxt.path}?{nxt.query}>; rel="next"'


@router.get("/loops", response_model=list[LoopOut], responses=UNAUTHORIZED)
async def list_loops(
    backend: Backend,
    request: Request,
    state: Annotated[State | None, Query(description="Only loops in this state.")] = None,
    cause: Annotated[Cause | None, Query(description="Only loops with this cause.")] = None,
    loop_type: Annotated[
        LoopType | None,
        Query(alias="type", description="Only loops of this type."),
    ] = None,
    area: Annotated[str | None, Query(description="Only loops of this plant area.")] = None,
    unit: Annotated[str | None, Query(description="Only loops of this process unit.")] = None,
    sort: Annotated[
        LoopSort,
        Query(description="`id` (default) or `priority`: the worst loops first."),
    ] = "id",
    limit: Annotated[int, Query(ge=1, le=100_000, description="Most loops returned.")] = 10_000,
    offset: Offset = 0,
) -> Response:
    """The loop-health table: every loop, its state, cause, since when, latest S and J, its
    priority and indices (at most one second old)."""
    table: LoopTable = request.app.state.loop_table
    rows, body = await table.get(backend.store)
    selected = select_loops(
        rows, state=state, cause=cause, loop_type=loop_type, area=area, unit=unit, sort=sort
    )
    if selected is not rows or offset > 0 or limit < len(rows):
        body = json.dumps(selected[offset : offset + limit], separators=(",", ":")).encode()
    response = Response(body, media_type="application/json")
    paginate(request, response, len(selected), limit, offset)
    return response


@router.get("/loops/{loop_id}", response_model=LoopDetail, responses={**NOT_FOUND, **UNAUTHORIZED})
async def get_loop_detail(backend: Backend, loop_id: LoopId) -> LoopDetail:
    """The loop and its latest diagnosis (the object of contracts §2)."""
    row = await get_loop(backend, loop_id)
    status = (await loop_statuses(backend.store, loop_id))[0]
    _, latest = await diagnosis_history(backend.store, row, limit=1)
    d = latest[0] if latest else None
    return LoopDetail(
        **loop_json(status),
        diagnosis=d["payload"] if d else None,
        window_start=iso(d["window_start_us"]) if d else None,
        window_end=iso(d["window_end_us"]) if d else None,
    )


@router.get(
    "/loops/{loop_id}/diagnoses",
    response_model=list[DiagnosisOut],
    responses={**NOT_FOUND, **UNAUTHORIZED},
)
async def list_diagnoses(
    backend: Backend,
    request: Request,
    response: Response,
    loop_id: LoopId,
    times: Annotated[TimeRange, Depends()],
    limit: Annotated[int, Query(ge=1, le=1000, description="Most diagnoses returned.")] = 100,
    offset: Offset = 0,
) -> list[DiagnosisOut]:
    """Diagnosis history (window end in [from, to)), newest first."""
    row = await get_loop(backend, loop_id)
    total, items = await diagnosis_history(
        backend.store, row, times.start_us, times.end_us, limit, offset
    )
    paginate(request, response, total, limit, offset)
    return [
        DiagnosisOut(
            created_at=iso_required(d["created_us"]),
            window_start=iso_required(d["window_start_us"]),
            window_end=iso_required(d["window_end_us"]),
            cause=d["cause"],
            state=d["state"],
            diagnosis=d["payload"],
        )
        for d in items
    ]


@router.get("/alerts", response_model=list[AlertOut], responses=UNAUTHORIZED)
async def get_alerts(
    backend: Backend,
    request: Request,
    response: Response,
    times: Annotated[TimeRange, Depends()],
    limit: Annotated[int, Query(ge=1, le=1000, description="Most alerts returned.")] = 100,
    offset: Offset = 0,
) -> list[AlertOut]:
    """Alert deliveries (created in [from, to)), newest first: delivered, pending (with the
    next try) or failed, with the attempts made and the last error."""
    total, rows = await list_alerts(backend.store, times.start_us, times.end_us, limit, offset)
    paginate(request, response, total, limit, offset)
    return [
        AlertOut(
            loop=a.loop, state=a.state, cause=a.cause, rule=a.rule, target=a.target,
            status=a.status, attempts=a.attempts, at=iso_required(a.created_us),
            delivered_at=iso(a.delivered_us),
            next_try_at=iso(a.next_try_us) if a.status == "pending" else None,
            key=a.key, last_error=a.last_error,
        )
        for a in rows
    ]  # fmt: skip


MAX_SAMPLES_PAGE = 10_000
"""Most samples one request returns."""
MAX_SAMPLES_SKIP = 10_000
"""Most samples one request may skip (``offset``): later pages follow the ``after`` cursor of
the ``Link`` header, which costs the same on any page. With the page, this bounds the rows one
request reads to (skip + page) per signal (``benchmarks/api_worst_request.py``)."""


def parse_cursor(after: str | None) -> tuple[int, int] | None:
    """``TIME_US:TAG`` from a ``Link`` header (the pattern is checked by the query)."""
    if after is None:
        return None
    t, tag = after.split(":")
    return int(t), int(tag)


def _sample_items(
    rows: Sequence[tuple[str, int, int, float | None, int]],
) -> list[dict[str, Any]]:
    stamps = iso_many([r[1] for r in rows] + [r[2] for r in rows])
    n = len(rows)
    return [
        {"time": stamps[k], "signal": sig, "value": value, "status": status,
         "received_at": stamps[n + k], "count": None, "min": None, "max": None}
        for k, (sig, _, _, value, status) in enumerate(rows)
    ]  # fmt: skip


async def _sample_page(
    store: Store,
    row: LoopRow,
    times: TimeRange,
    signal: Sequence[str] | None,
    limit: int,
    offset: int,
    cursor: tuple[int, int] | None,
    resolution: str,
) -> tuple[list[dict[str, Any]], tuple[int, int] | None, bool]:
    """One page of samples as JSON-ready rows, the last row's cursor, whether more follow."""
    start, end = times.start_us, times.end_us
    items: list[dict[str, Any]]
    if resolution == "hour":
        hours = await read_hours(store, row, start, end, limit + 1, signal, cursor, offset)
        page = hours[:limit]
        items = [
            {"time": t, "signal": h.signal, "value": h.mean, "status": 0,
             "received_at": None, "count": h.n, "min": h.low, "max": h.high}
            for t, h in zip(iso_many([h.hour_us for h in page]), page, strict=True)
        ]  # fmt: skip
        last = (page[-1].hour_us, row.tags[page[-1].signal]) if page else None
        more = len(hours) > limit
    else:
        if start is None and end is None:
            newest = await store.latest_sample_us(row)
            if newest is not None:
                start, end = newest - 3_600_000_000, newest + 1
        rows = await store.read_samples(row, start, end, limit + 1, signal, cursor, offset)
        page_rows = rows[:limit]
        # the rows become JSON off the event loop: /healthz and the page stay quick meanwhile
        items = await asyncio.to_thread(_sample_items, page_rows)
        last = (page_rows[-1][1], row.tags[page_rows[-1][0]]) if page_rows else None
        more = len(rows) > limit
    return items, last, more


@router.get(
    "/loops/{loop_id}/samples",
    response_model=list[SampleOut],
    responses={**NOT_FOUND, **UNAUTHORIZED},
)
async def list_samples(
    backend: Backend,
    request: Request,
    loop_id: LoopId,
    times: Annotated[TimeRange, Depends()],
    signal: Annotated[
        list[Literal["sp", "pv", "op", "mv", "mode"]] | None,
        Query(description="Only these signals (repeat the parameter for several)."),
    ] = None,
    limit: Annotated[
        int, Query(ge=1, le=MAX_SAMPLES_PAGE, description="Most samples returned.")
    ] = MAX_SAMPLES_PAGE,
    offset: Annotated[
        int,
        Query(
            ge=0,
            le=MAX_SAMPLES_SKIP,
            description="Samples to skip (at most 10,000: for later pages follow the Link "
            "header, which carries the 'after' cursor).",
        ),
    ] = 0,
    after: Annotated[
        str | None,
        Query(
            pattern=r"^\d{1,19}:\d{1,10}$",
            description="Cursor from the Link header: continue after this position.",
        ),
    ] = None,
    resolution: Annotated[
        Literal["raw", "hour"],
        Query(
            description="raw: the stored samples; hour: hourly roll-ups (count, mean, min, "
            "max of the Good values), kept for years after the samples are deleted."
        ),
    ] = "raw",
) -> Response:
    """Stored samples in [from, to), oldest first; without ``from`` and ``to``, the last hour
    up to the newest stored sample (hourly: everything kept). A ``Link`` header points to the
    next page, if any. One request reads at most (offset + limit) rows per signal, whatever
    the span."""
    row = await get_loop(backend, loop_id)
    cursor = parse_cursor(after)
    items, last, more = await _sample_page(
        backend.store, row, times, signal, limit, offset, cursor, resolution
    )
    body = await asyncio.to_thread(json.dumps, items, separators=(",", ":"))
    response = Response(body, media_type="application/json")
    if more and last is not None:
        # the next page by keyset, so that it costs what the first did; a relative link (RFC
        # 8288 allows it), never one built from the Host header
        nxt = request.url.remove_query_params("offset").include_query_params(
            after=f"{last[0]}:{last[1]}", limit=limit
        )
        response.headers["Link"] = f'<{nxt.path}?{nxt.query}>; rel="next"'
    return response


@router.get("/actions", response_model=list[ActionOut], responses=UNAUTHORIZED)
async def list_actions(
    backend: Backend,
    request: Request,
    response: Response,
    loop: Annotated[
        str | None, Query(description="Only this loop's action.", max_length=64)
    ] = None,
    limit: Annotated[int, Query(ge=1, le=100_000, description="Most actions returned.")] = 10_000,
    offset: Offset = 0,
) -> list[ActionOut]:
    """The suggested-action table (open actions), most urgent first, then oldest first."""
    rows = [a for a in await active_actions(backend.store) if loop is None or a["loop"] == loop]
    paginate(request, response, len(rows), limit, offset)
    return [
        ActionOut(
            loop=a["loop"],
            cause=a["cause"],
            code=a["code"],
            action=a["text"],
            priority=a["priority"],
            since=iso_required(a["since_us"]),
        )
        for a in rows[offset : offset + limit]
    ]


@router.get("/sources", response_model=list[SourceOut], responses=UNAUTHORIZED)
async def list_sources(backend: Backend) -> list[SourceOut]:
    """Every data source: up, down (since its first failure) or unknown (not yet connected)."""
    return [
        SourceOut(
            name=h.name,
            protocol=h.protocol,
            state=h.state,
            since=iso(h.since_us),
            last_good_sample_at=iso(h.last_good_sample_us),
            failures=h.failures,
            last_error=h.last_error,
        )
        for h in backend.sources()
    ]


@router.get("/storage", response_model=StorageOut, responses=UNAUTHORIZED)
async def storage_health(backend: Backend) -> StorageOut:
    """Where this process's samples go: the database (down while commits fail), the durable
    buffer (down while its disk fails), samples held in memory and dropped."""
    return backend.storage_health()


@router.post(
    "/loops/{loop_id}/diagnose",
    response_model=DiagnoseNow,
    dependencies=[Depends(require_write_key)],
    responses={
        **NOT_FOUND,
        **UNAUTHORIZED,
        403: {"description": "No API key configured"},
        409: {"description": "The loop is not scheduled or its diagnosis failed"},
    },
)
async def diagnose_now(backend: Backend, loop_id: LoopId) -> DiagnoseNow:
    """Diagnose the loop now on its rolling window (the scheduler's job, run out of turn).
    Needs the API key. Reads only from the store; nothing is written to the plant."""
    await get_loop(backend, loop_id)
    cause = await backend.diagnose_now(loop_id)
    if cause is None:
        raise HTTPException(
            409, f"loop {loop_id!r} is not scheduled here or its diagnosis failed (see the log)"
        )
    return DiagnoseNow(loop=loop_id, cause=cause)
