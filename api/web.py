"""The web page: loop-health table, loop detail (trends, PV(OP) plot), actions, stiction report.

Server-rendered with Jinja2; plots drawn in the browser by the vendored uPlot (MIT, in
``static/``) and a small canvas routine for the PV(OP) plot. No CDN: the page works on a plant
network without internet access. Pages need the API key exactly when reads do.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import HTMLResponse
from fastapi.templating import Jinja2Templates
from jinja2 import pass_context

from plantcheck import __version__
from plantcheck.api.deps import Backend, TimeRange, get_loop, iso, require_read_key
from plantcheck.api.health_reports import (
    STATES,
    build_health_report,
    build_maintenance_report,
)
from plantcheck.api.loop_table import LoopSort, LoopTable, select_loops
from plantcheck.api.reports import build_report
from plantcheck.storage.plant_oscillations import latest_plant_oscillations
from plantcheck.storage.plant_summary import plant_summary
from plantcheck.storage.results import active_actions, diagnosis_history, loop_statuses
from plantcheck.storage.window import HELD

HERE = Path(__file__).parent
templates = Jinja2Templates(directory=HERE / "templates")
templates.env.globals["version"] = __version__
templates.env.filters["iso"] = iso


@pass_context
def _url_for(context: dict[str, Any], name: str, /, **params: Any) -> str:
    """A root-relative link: built from the route, never from the request's Host header (a
    spoofed Host would otherwise choose where the page's scripts come from)."""
    request: Request = context["request"]
    return str(request.scope.get("root_path", "")) + str(request.app.url_path_for(name, **params))


templates.env.globals["url_for"] = _url_for

router = APIRouter(dependencies=[Depends(require_read_key)], include_in_schema=False)

MAX_POINTS = 2400
"""Most points per trend sent to the browser (the window is decimated by striding)."""


def _page(request: Request, backend: Backend, name: str, context: dict[str, Any]) -> HTMLResponse:
    """Render a page with the banner of the sources that are down (every page shows it: a
    table of verdicts over stale data must say so)."""
    down = [h for h in backend.sources() if h.state == "down"]
    return templates.TemplateResponse(request, name, {**context, "sources_down": down})


CLOCK_TOLERANCE_S = 300.0
"""Plant time this far from the server's clock is said on the loop page (s)."""


def plant_clock_note(newest_us: int | None, now_us: int) -> str:
    """A sentence when the loop's newest sample is far from this server's clock: its trends and
    history run in plant time (the source's timestamps), which then is not the wall clock of
    the "since" columns (issue 47: the demo's simulated plant ran hours ahead)."""
    if newest_us is None:
        return ""
    ahead_s = (newest_us - now_us) / 1e6
    if abs(ahead_s) < CLOCK_TOLERANCE_S:
        return ""
    h = abs(ahead_s) / 3600
    span = f"{h:.1f} h" if h >= 1 else f"{abs(ahead_s) / 60:.0f} min"
    way = "ahead of" if ahead_s > 0 else "behind"
    return (
        f"Plant time (the source's timestamps, shown in the trends and the history) runs {span} "
        f"{way} this server's clock: a simulator, a replay or a plant clock that is off."
    )


def _series(x: np.ndarray) -> list[float | None]:
    return [None if not np.isfinite(v) else round(float(v), 4) for v in x]


@router.get("/", response_class=HTMLResponse)
async def health_page(
    request: Request,
    backend: Backend,
    state: str = "",
    cause: str = "",
    loop_type: Annotated[str, Query(alias="type")] = "",
    area: str = "",
    sort: LoopSort = "priority",
) -> HTMLResponse:
    """The loop-health table, the worst loops first, filtered as ``GET /api/v1/loops``
    filters (an empty filter: all), sortable by any column in the browser."""
    table: LoopTable = request.app.state.loop_table
    rows, _ = await table.get(backend.store)
    loops = select_loops(
        rows,
        state=state or None,
        cause=cause or None,
        loop_type=loop_type or None,
        area=area or None,
        sort=sort,
    )
    counts: dict[str, int] = {}
    for lp in loops:
        counts[lp["state"]] = counts.get(lp["state"], 0) + 1
    choices = {
        key: sorted({str(r[key]) for r in rows if r[key]})
        for key in ("state", "cause", "type", "area")
    }
    chosen = {"state": state, "cause": cause, "type": loop_type, "area": area, "sort": sort}
    return _page(
        request,
        backend,
        "index.html",
        {
            "loops": loops,
            "total": len(rows),
            "counts": counts,
            "choices": choices,
            "chosen": chosen,
            "title": "Loop health",
        },
    )


@router.get("/loop/{loop_id}", response_class=HTMLResponse)
async def loop_page(request: Request, backend: Backend, loop_id: str) -> HTMLResponse:
    """One loop: state, latest diagnosis, SP/PV/OP(/MV) trends over its last window, PV(OP)."""
    row = await get_loop(backend, loop_id)
    status = (await loop_statuses(backend.store, loop_id))[0]
    # the action as the actions page shows it: one text, one since (issue 47)
    action = next((a for a in await active_actions(backend.store) if a["loop"] == loop_id), None)
    _, hist = await diagnosis_history(backend.store, row, limit=20)
    latest = hist[0] if hist else None
    if latest is not None:
        start, end = latest["window_start_us"], latest["window_end_us"]
    else:
        newest = await backend.store.latest_sample_us(row)
        end = (newest or 0) + 1
        start = end - 3_600_000_000
    # held as the scheduler holds them: an OPC UA valve stuck for an hour has one MV sample
    win = await backend.store.read_window(
        row, start, end, hold=backend.held_signals.get(loop_id, HELD)
    )
    newest = await backend.store.latest_sample_us(row)
    stride = max(1, int(np.ceil(win.t_us.size / MAX_POINTS)))
    plot: dict[str, Any] = {"t": (win.t_us[::stride] / 1e6).round(3).tolist()}
    for sig in ("sp", "pv", "op", "mv"):
        if sig in win.signals:
            plot[sig] = _series(win.values[sig][::stride])
    return _page(
        request,
        backend,
        "loop.html",
        {
            "loop": status,
            "action": action,
            "diagnosis": latest["payload"] if latest else None,
            "history": hist,
            "plot": plot,
            "clock_note": plant_clock_note(newest, time.time_ns() // 1000),
            "title": f"Loop {loop_id}",
        },
    )


@router.get("/plant", response_class=HTMLResponse)
async def plant_page(request: Request, backend: Backend) -> HTMLResponse:
    """The plant at a glance: counts by state and cause per area against a week before, and
    the loops oscillating together with their source."""
    summary = await plant_summary(backend.store, time.time_ns() // 1000)
    latest = await latest_plant_oscillations(backend.store)
    at_us, groups = latest if latest is not None else (None, [])
    return _page(
        request,
        backend,
        "plant.html",
        {
            "summary": summary,
            "groups": groups,
            "groups_at_us": at_us,
            "states": STATES,
            "title": "Plant",
        },
    )


@router.get("/weekly", response_class=HTMLResponse)
async def weekly_page(
    request: Request, backend: Backend, times: Annotated[TimeRange, Depends()]
) -> HTMLResponse:
    """The loop-health report: time in each state, indices against the week before, actions
    opened and closed (``GET /api/v1/reports/weekly``)."""
    report = await build_health_report(backend, times)
    return _page(
        request,
        backend,
        "weekly.html",
        {"report": report, "states": STATES,
         "title": "Loop-health report"},
    )  # fmt: skip


@router.get("/maintenance", response_class=HTMLResponse)
async def maintenance_page(request: Request, backend: Backend) -> HTMLResponse:
    """Valves ranked for maintenance (``GET /api/v1/reports/maintenance``)."""
    report = await build_maintenance_report(backend)
    return _page(request, backend, "maintenance.html", {"report": report, "title": "Maintenance"})


@router.get("/actions", response_class=HTMLResponse)
async def actions_page(request: Request, backend: Backend) -> HTMLResponse:
    """The suggested-action table."""
    rows = await active_actions(backend.store)
    return _page(request, backend, "actions.html", {"actions": rows, "title": "Suggested actions"})


@router.get("/stiction", response_class=HTMLResponse)
async def stiction_page(
    request: Request, backend: Backend, times: Annotated[TimeRange, Depends()]
) -> HTMLResponse:
    """Each valve's S over time, its limit and the projection to the limit."""
    report = await build_report(backend, times)
    return _page(
        request,
        backend,
        "stiction.html",
        {"report": report.model_dump(), "title": "Valve stiction report"},
    )
