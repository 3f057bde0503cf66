"""``GET /api/v1/reports/stiction``: per valve, S and J over time, the weekly medians, the
robust trend and the date S is projected to pass the valve's limit.

The estimates were made by the scheduler (the diagnosis chain's reliable S, J); this route only
summarises them: weekly medians and the Theil–Sen line of ``diagnosis.stiction_trend``
(Bacci di Capaci & Scali 2014), over the requested period.
"""

from __future__ import annotations

import csv
import io
import time
from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, Depends, Query, Response

from plantcheck.api.deps import Backend, TimeRange, iso, iso_required, require_read_key
from plantcheck.api.models import StictionPoint, StictionReport, ValveReport, WeekOut
from plantcheck.diagnosis.stiction_trend import TrendParams, stiction_trend
from plantcheck.storage.results import stiction_history

router = APIRouter(prefix="/api/v1", dependencies=[Depends(require_read_key)])

WEEK_US = 7 * 24 * 3600 * 1_000_000
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
    loop: str, rows: list[tuple[int, float, float | None, str]], limit: float
) -> ValveReport:
    """One valve's report from its (at_us, S, J, source) estimates."""
    at = np.array([r[0] for r in rows], dtype=np.int64)
    S = np.array([r[1] for r in rows], dtype=np.float64)
    J = np.array([np.nan if r[2] is None else r[2] for r in rows], dtype=np.float64)
    tr = stiction_trend(at / 1e6, S, J, np.ones(at.size, bool), TrendParams(limit=limit))
    crossing = tr.projected_crossing_s
    return ValveReport(
        loop=loop,
        limit=limit,
        current_S=tr.current_S,
        current_J=tr.current_J,
        slope_per_week=tr.slope_per_week,
        above_limit=tr.above_limit,
        projected_crossing=iso(int(crossing * 1e6)) if crossing is not None else None,
        note=tr.note,
        weeks=_weeks(at, S, J),
        estimates=[
            StictionPoint(time=iso_required(a), S=s, J=j, source=src) for a, s, j, src in rows
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
                ]
            )
    return buf.getvalue()


async def build_report(backend: Backend, times: TimeRange) -> StictionReport:
    history = await stiction_history(backend.store, times.start_us, times.end_us)
    limits = backend.stiction_limits
    return StictionReport(
        generated_at=iso_required(time.time_ns() // 1000),
        start=iso(times.start_us),
        end=iso(times.end_us),
        valves=[
            valve_report(loop, rows, limits.get(loop, TrendParams().limit))
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
