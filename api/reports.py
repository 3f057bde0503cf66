"""``GET /api/v1/reports/stiction``: per valve, S and J over time, the weekly medians, the
robust trend and the date S is projected to pass the valve's limit.

The estimates were made by the scheduler (the diagnosis chain's best S, J with its method);
this route only summarises them: weekly medians and the Theil–Sen line of
``diagnosis.stiction_trend`` (Bacci di Capaci & Scali 2014) over the requested period, from one
method per valve (a Hammerstein S and an apparent stiction are not the same quantity).
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
from plantcheck.storage.results import METHOD_RANK, StoredEstimate, stiction_history

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


def trend_method(rows: list[StoredEstimate], min_estimates: int) -> str | None:
    """The method a valve's trend is read from: the most direct one with ``min_estimates``
    reliable estimates, else the most direct one with any reliable estimate, else the most
    direct one present (whose unreliable points then give no trend)."""
    present = [m for m in METHOD_RANK if any(r.method == m for r in rows)]
    for enough in (min_estimates, 1):
        for m in present:
            if sum(r.method == m and r.reliable for r in rows) >= enough:
                return m
    return present[0] if present else None


def valve_report(loop: str, rows: list[StoredEstimate], limit: float) -> ValveReport:
    """One valve's report from its estimates: the trend, weekly medians and current S come
    from one method (``trend_method``); every estimate is listed with its method."""
    params = TrendParams(limit=limit)
    method = trend_method(rows, params.min_estimates)
    used = [r for r in rows if r.method == method]
    at = np.array([r.at_us for r in used], dtype=np.int64)
    S = np.array([r.S for r in used], dtype=np.float64)
    J = np.array([np.nan if r.J is None else r.J for r in used], dtype=np.float64)
    ok = np.array([r.reliable for r in used], dtype=bool)
    tr = stiction_trend(at / 1e6, S, J, ok, params)
    crossing = tr.projected_crossing_s
    note = tr.note
    others = len(rows) - int(ok.sum())
    if method is not None and others:
        note += (
            f" (from {int(ok.sum())} reliable {method} estimates; {others} other "
            "estimates listed, not in the trend)"
        )
    return ValveReport(
        loop=loop,
        limit=limit,
        current_S=tr.current_S,
        current_J=tr.current_J,
        slope_per_week=tr.slope_per_week,
        above_limit=tr.above_limit,
        projected_crossing=iso(int(crossing * 1e6)) if crossing is not None else None,
        note=note,
        trend_method=method,
        weeks=_weeks(at[ok], S[ok], J[ok]),
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
