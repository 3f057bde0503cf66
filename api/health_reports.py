"""What a plant reads weekly (issue 49 item 5): ``GET /api/v1/reports/weekly``, the loop-health
report (per loop the time in each state, its indices against the period before, actions
opened and closed), and ``GET /api/v1/reports/maintenance``, the valves ranked by the date
their stiction is projected to pass its limit, with their travel and reversals. JSON or CSV;
the pages ``/weekly`` and ``/maintenance`` show the same. Both only read what the scheduler
stored (``storage.health_report``, the valves' trends of ``storage.trends``).
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Iterable, Sequence
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Query, Response

from plantcheck.api.deps import Backend, TimeRange, iso, iso_required, require_read_key
from plantcheck.api.models import (
    ActionEvent,
    HealthReport,
    LoopWeekOut,
    MaintenanceReport,
    MaintenanceValve,
)
from plantcheck.diagnosis.tuning_proposal import VALVE_CAUSES
from plantcheck.storage.health_report import TRENDED, LoopPeriod, loop_periods
from plantcheck.storage.plant_summary import WEEK_US
from plantcheck.storage.results import active_actions, loop_statuses
from plantcheck.storage.trends import read_trends

router = APIRouter(prefix="/api/v1", dependencies=[Depends(require_read_key)])

STATES = ("fault", "warning", "unknown", "ok")
"""The states as the reports and pages list them: the worst first."""
Format = Annotated[
    Literal["json", "csv"], Query(alias="format", description="json (default) or csv.")
]
CSV_RESPONSE: dict[int | str, dict[str, Any]] = {
    200: {"content": {"text/csv": {}}, "description": "The report (JSON, or CSV)"},
    401: {"description": "Missing or wrong X-API-Key header"},
}


def _events(items: Iterable[dict[str, Any]]) -> list[ActionEvent]:
    return [
        ActionEvent(cause=a["cause"], code=a["code"], text=a["text"], at=iso_required(a["at_us"]))
        for a in items
    ]


def _week(p: LoopPeriod, hours: float) -> LoopWeekOut:
    return LoopWeekOut(
        loop=p.loop, area=p.area, criticality=p.criticality, state=p.state, cause=p.cause,
        diagnoses=p.diagnoses,
        hours_in_state={s: round(share * hours, 2) for s, share in p.state_share.items()},
        kpis=p.kpis, kpis_before=p.kpis_before,
        opened=_events(p.opened), closed=_events(p.closed),
    )  # fmt: skip


async def build_health_report(backend: Backend, times: TimeRange) -> HealthReport:
    """The loop-health report over [from, to) (default: the last seven days)."""
    end = times.end_us if times.end_us is not None else time.time_ns() // 1000
    start = times.start_us if times.start_us is not None else end - WEEK_US
    periods = await loop_periods(backend.store, start, end)
    hours = (end - start) / 3.6e9
    return HealthReport(
        generated_at=iso_required(time.time_ns() // 1000),
        start=iso_required(start),
        end=iso_required(end),
        loops=[_week(p, hours) for p in periods],
    )


def _csv(header: Sequence[str], rows: Iterable[Sequence[object]], name: str) -> Response:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(["" if v is None else v for v in row] for row in rows)
    return Response(
        buf.getvalue(),
        media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="{name}"'},
    )


@router.get("/reports/weekly", response_model=HealthReport, responses=CSV_RESPONSE)
async def weekly_report(
    backend: Backend, times: Annotated[TimeRange, Depends()], fmt: Format = "json"
) -> HealthReport | Response:
    """Per loop over [from, to) (default: the last seven days): hours in each state, the mean
    of its indices against the period before, and the actions opened and closed."""
    report = await build_health_report(backend, times)
    if fmt == "json":
        return report
    header = ["loop", "area", "criticality", "state", "cause", "diagnoses"]
    header += [f"hours_{s}" for s in STATES]
    header += [f"{k}{suffix}" for k in TRENDED for suffix in ("", "_before")]
    header += ["actions_opened", "actions_closed"]
    rows = (
        [lp.loop, lp.area, lp.criticality, lp.state, lp.cause, lp.diagnoses]
        + [lp.hours_in_state.get(s, 0.0) for s in STATES]
        + [v for k in TRENDED for v in (lp.kpis.get(k), lp.kpis_before.get(k))]
        + [len(lp.opened), len(lp.closed)]
        for lp in report.loops
    )
    return _csv(header, rows, "loop-health-report.csv")


def _rank(v: MaintenanceValve) -> tuple[int, str, float]:
    """Past the limit first (largest S first), then by the projected date, then the rest."""
    if v.above_limit:
        return 0, "", -(v.current_S or 0.0)
    if v.projected_crossing is not None:
        return 1, v.projected_crossing, 0.0
    return 2, "", -(v.current_S or 0.0)


async def build_maintenance_report(backend: Backend) -> MaintenanceReport:
    """The valves with a stiction trend or a valve cause now, worst first (``_rank``)."""
    trends = await read_trends(backend.store)
    texts = {a["loop"]: a["text"] for a in await active_actions(backend.store)}
    limits = backend.stiction_limits
    valves = []
    for s in await loop_statuses(backend.store):
        trend = trends.get(s.id)
        if trend is None and s.cause not in VALVE_CAUSES:
            continue
        k = s.kpis or {}
        valves.append(
            MaintenanceValve(
                loop=s.id, area=s.area, criticality=s.criticality, cause=s.cause,
                current_S=trend.current_S if trend else s.S,
                limit=trend.limit if trend else limits.get(s.id, 2.0),
                slope_per_week=trend.slope_per_week if trend else None,
                above_limit=trend.above_limit if trend else False,
                projected_crossing=iso(trend.projected_crossing_us) if trend else None,
                trend_method=trend.method if trend else None,
                op_travel_per_day=k.get("op_travel_per_day"),
                op_reversals_per_day=k.get("op_reversals_per_day"),
                mv_travel_per_day=k.get("mv_travel_per_day"),
                mv_reversals_per_day=k.get("mv_reversals_per_day"),
                action=texts.get(s.id),
            )
        )  # fmt: skip
    return MaintenanceReport(
        generated_at=iso_required(time.time_ns() // 1000), valves=sorted(valves, key=_rank)
    )


@router.get("/reports/maintenance", response_model=MaintenanceReport, responses=CSV_RESPONSE)
async def maintenance_report(
    backend: Backend, fmt: Format = "json"
) -> MaintenanceReport | Response:
    """Valves ranked for maintenance: past their stiction limit first, then by the date S is
    projected to pass it, with their travel and reversals per day."""
    report = await build_maintenance_report(backend)
    if fmt == "json":
        return report
    header = list(MaintenanceValve.model_fields)
    return _csv(header, ([getattr(v, k) for k in header] for v in report.valves),
                "maintenance-report.csv")  # fmt: skip
