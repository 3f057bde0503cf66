"""``GET /api/v1/reports/stiction``: per valve, S and J over time, the weekly medians, the
robust trend and the date S is projected to pass the valve's limit.

The estimates were made by the scheduler (the diagnosis chain's best S, J with its method),
and each valve's trend was computed when its latest estimate was stored (``storage/trends``:
the Theil–Sen line of ``diagnosis.stiction_trend``, Bacci di Capaci & Scali 2014, over all its
estimates of one method). This route only reads them and lists the requested period's
estimates with the weekly medians of the trend's method.
"""

from __future__ import annotations

import csv
import io
import time
from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query, Response

from plantcheck.api.deps import Backend, TimeRange, iso, iso_required, require_read_key
from plantcheck.api.models import StictionPoint, StictionReport, ValveReport, WeekOut
from plantcheck.diagnosis.stiction_trend import TrendParams
from plantcheck.storage.plant_summary import WEEK_US
from plantcheck.storage.results import (
    LoopStatus,
    active_actions,
    count_estimates,
    loop_statuses,
    stiction_history,
)
from plantcheck.storage.trends import StoredEstimate, StoredTrend, read_trends

router = APIRouter(prefix="/api/v1", dependencies=[Depends(require_read_key)])

MONDAY_US = 4 * 24 * 3600 * 1_000_000
"""1970-01-01 was a Thursday: weeks start on Monday 00:00 UTC."""


def _weeks(at: np.ndarray, S: np.ndarray, J: np.ndarray) -> list[WeekOut]:
    week = (at + MONDAY_US) // WEEK_US
    out = []
    for w in np.unique(week):
        m = week == w
        j = J[m][np.isfinite(J[m])]
        out.append(
            WeekOut(
                week_start=iso_required(int(w * WEEK_US - MONDAY_US)),
                S_median=round(float(np.median(S[m])), 3),
                J_median=round(float(np.median(j)), 3) if j.size else None,
                estimates=int(m.sum()),
            )
        )
    return out


def valve_report(
    loop: str,
    rows: list[StoredEstimate],
    trend: StoredTrend | None,
    limit: float,
    status: LoopStatus | None = None,
    action: str | None = None,
) -> ValveReport:
    """One valve's report: its estimates in the period, each with its method, the weekly
    medians of the trend's method, and the trend stored with its latest estimate; beside
    them the S and the action the loop table and the actions page show (one truth per loop,
    issue 47)."""
    method = trend.method if trend is not None else None
    used = [r for r in rows if r.method == method and r.reliable]
    at = np.array([r.at_us for r in used], dtype=np.int64)
    S = np.array([r.S for r in used], dtype=np.float64)
    J = np.array([np.nan if r.J is None else r.J for r in used], dtype=np.float64)
    if trend is None:
        note = "no trend yet: it is computed when the valve's next estimate is stored"
    else:
        note = trend.note
        others = len(rows) - len(used)
        if method is not None and others:
            note += (
                f" (from {trend.used} reliable {method} estimates; {others} other "
                "estimates listed, not in the trend)"
            )
    return ValveReport(
        loop=loop,
        limit=trend.limit if trend is not None else limit,
        current_S=trend.current_S if trend is not None else None,
        current_J=trend.current_J if trend is not None else None,
        slope_per_week=trend.slope_per_week if trend is not None else None,
        above_limit=trend.above_limit if trend is not None else False,
        projected_crossing=iso(trend.projected_crossing_us) if trend is not None else None,
        note=note,
        trend_method=method,
        latest_S=status.S if status is not None else None,
        latest_J=status.J if status is not None else None,
        latest_method=status.S_method if status is not None else None,
        latest_at=iso(status.S_at_us) if status is not None else None,
        action=action,
        weeks=_weeks(at, S, J),
        estimates=[
            StictionPoint(
                time=iso_required(r.at_us),
                S=r.S,
                J=r.J,
                source=r.source,
                method=r.method,
                reliable=r.reliable,
            )
            for r in rows
        ],
    )


CSV_COLUMNS = (
    "loop",
    "time",
    "S",
    "J",
    "source",
    "limit",
    "current_S",
    "slope_per_week",
    "projected_crossing",
    "method",
    "reliable",
)


def report_csv(report: StictionReport) -> str:
    """One row per estimate, with its valve's trend repeated on each row."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for v in report.valves:
        for e in v.estimates:
            w.writerow(
                [
                    v.loop,
                    e.time,
                    e.S,
                    "" if e.J is None else e.J,
                    e.source,
                    v.limit,
                    "" if v.current_S is None else round(v.current_S, 3),
                    "" if v.slope_per_week is None else round(v.slope_per_week, 4),
                    v.projected_crossing or "",
                    e.method,
                    "true" if e.reliable else "false",
                ]
            )
    return buf.getvalue()


MAX_REPORT_ESTIMATES = 200_000
"""Most stiction estimates one report reads (a year of hourly estimates of 20 valves; a plant
of hundreds asks for a shorter span)."""


async def build_report(backend: Backend, times: TimeRange) -> StictionReport:
    n = await count_estimates(backend.store, times.start_us, times.end_us)
    if n > MAX_REPORT_ESTIMATES:
        raise HTTPException(
            422,
            [
                {
                    "loc": ["query", "from"],
                    "msg": f"the span holds {n} stiction estimates, more than one report reads "
                    f"({MAX_REPORT_ESTIMATES}): ask a shorter span with 'from' and 'to'",
                    "type": "value_error",
                }
            ],
        )
    history = await stiction_history(backend.store, times.start_us, times.end_us)
    trends = await read_trends(backend.store)
    statuses = {s.id: s for s in await loop_statuses(backend.store)}
    texts = {a["loop"]: a["text"] for a in await active_actions(backend.store)}
    limits = backend.stiction_limits
    return StictionReport(
        generated_at=iso_required(time.time_ns() // 1000),
        start=iso(times.start_us),
        end=iso(times.end_us),
        valves=[
            valve_report(
                loop,
                rows,
                trends.get(loop),
                limits.get(loop, TrendParams().limit),
                statuses.get(loop),
                texts.get(loop),
            )
            for loop, rows in history.items()
        ],
    )


@router.get(
    "/reports/stiction",
    response_model=StictionReport,
    responses={
        200: {"content": {"text/csv": {}}, "description": "The report (JSON, or CSV)"},
        401: {"description": "Missing or wrong X-API-Key header"},
    },
)
async def stiction_report(
    backend: Backend,
    times: Annotated[TimeRange, Depends()],
    fmt: Annotated[
        Literal["json", "csv"], Query(alias="format", description="json (default) or csv.")
    ] = "json",
) -> StictionReport | Response:
    """Stiction trend report for maintenance planning: each valve's S and J (% of travel)
    over [from, to), weekly medians, trend per week, projected date S passes its limit."""
    report = await build_report(backend, times)
    if fmt == "csv":
        return Response(
            report_csv(report),
            media_type="text/csv",
            headers={"Content-Disposition": 'attachment; filename="stiction-report.csv"'},
        )
    return report
