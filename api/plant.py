"""The plant as a whole (issue 49): ``GET /api/v1/plant/summary``, loops counted by state and
by cause for the plant and per area, now and a week before, with the change; and
``GET /api/v1/plant/oscillations``, the groups of loops oscillating together with their likely
source, as the plant-wide pass last stored them (``service/plant_oscillations.py``)."""

from __future__ import annotations

import time
from typing import Annotated

from fastapi import APIRouter, Depends, Query

from plantcheck.api.deps import Backend, iso_required, require_read_key
from plantcheck.api.models import AreaCounts, Counts, OscillationGroupOut, PlantSummaryOut
from plantcheck.storage.plant_oscillations import latest_plant_oscillations
from plantcheck.storage.plant_summary import AreaSummary, plant_summary
from plantcheck.storage.plant_summary import Counts as StoredCounts

router = APIRouter(prefix="/api/v1", dependencies=[Depends(require_read_key)])


def _counts(c: StoredCounts) -> Counts:
    return Counts(loops=c.loops, by_state=dict(c.by_state), by_cause=dict(c.by_cause))


def _area(a: AreaSummary) -> AreaCounts:
    by_state, by_cause = a.change()
    return AreaCounts(
        area=a.area,
        now=_counts(a.now),
        then=_counts(a.then),
        change_by_state=by_state,
        change_by_cause=by_cause,
    )


@router.get("/plant/summary", response_model=PlantSummaryOut)
async def get_plant_summary(
    backend: Backend,
    days: Annotated[
        float, Query(gt=0, le=366, description="How far back 'then' is, days (default a week).")
    ] = 7.0,
) -> PlantSummaryOut:
    """Loops by state and by cause, for the plant and per area, now and `days` before."""
    s = await plant_summary(backend.store, time.time_ns() // 1000, int(days * 86_400e6))
    return PlantSummaryOut(
        at=iso_required(s.at_us),
        then=iso_required(s.then_us),
        plant=_area(s.plant),
        areas=[_area(a) for a in s.areas],
    )


@router.get("/plant/oscillations", response_model=list[OscillationGroupOut])
async def get_plant_oscillations(backend: Backend) -> list[OscillationGroupOut]:
    """Groups of loops oscillating at a common period (harmonics considered), each with its
    likely source and the evidence; empty before the first plant-wide pass."""
    latest = await latest_plant_oscillations(backend.store)
    if latest is None:
        return []
    at_us, groups = latest
    return [OscillationGroupOut(**g, at=iso_required(at_us)) for g in groups]
