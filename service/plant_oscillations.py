"""The plant-wide oscillation pass (issue 49 item 3): every diagnosis period, the loops whose
latest diagnosis found an oscillation are compared over one common span of time, and the groups
of loops oscillating together, each with its likely source, are stored for
``GET /api/v1/plant/oscillations`` (``diagnosis.plant_oscillation``: Thornhill, Huang & Zhang
2003).

The span is the scheduler's window ending at the earliest of the members' latest diagnosed
windows (plant time: a simulator or a plant clock ahead of this server is judged on its own
time base, as the diagnoses are). A loop whose latest diagnosis ended more than half a window
before the others' is not diagnosed any more (its source is down) and stays out.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from dataclasses import asdict
from typing import Any

import numpy as np

from plantcheck.diagnosis.plant_oscillation import (
    OscillatingLoop,
    own_oscillation,
    plant_oscillations,
)
from plantcheck.service.background import BackgroundTask
from plantcheck.service.scheduler import LoopSchedule
from plantcheck.storage.plant_oscillations import (
    LatestDiagnosis,
    latest_diagnoses,
    record_plant_oscillations,
)
from plantcheck.storage.store import Store

log = logging.getLogger("plantcheck.scheduler")


def _members(
    latest: Sequence[LatestDiagnosis], window_s: float
) -> tuple[list[LatestDiagnosis], int]:
    """The oscillating loops diagnosed lately, and the end of their common span (µs)."""
    osc = [d for d in latest if d.payload.get("oscillations")]
    if len(osc) < 2:
        return [], 0
    newest = max(d.window_end_us for d in osc)
    fresh = [d for d in osc if newest - d.window_end_us <= window_s * 1e6 / 2]
    return fresh, min((d.window_end_us for d in fresh), default=0)


async def plant_pass(
    store: Store, schedules: Sequence[LoopSchedule], window_s: float
) -> list[dict[str, Any]]:
    """The groups of loops oscillating together now (``OscillationGroup`` as dicts)."""
    by_name = {s.name: s for s in schedules}
    latest = [d for d in await latest_diagnoses(store) if d.loop in by_name]
    members, end_us = _members(latest, window_s)
    if len(members) < 2:
        return []
    ts = max(float(d.payload.get("sample_time_s") or 1.0) for d in members)
    start_us = end_us - int(window_s * 1e6)
    rows = await store.loops()
    loops: list[OscillatingLoop] = []
    for d in members:
        win = await store.read_window(
            rows[d.loop], start_us, end_us, sample_time_s=ts, hold=by_name[d.loop].hold
        )
        pv = win.values.get("pv")
        if pv is None:
            continue
        sp = win.values.get("sp")
        error = (sp - pv) if sp is not None and np.isfinite(sp).any() else -pv
        own, rank = own_oscillation(d.payload)
        periods = tuple(float(o["period_s"]) for o in d.payload["oscillations"])
        loops.append(OscillatingLoop(d.loop, periods, np.asarray(error, float), own, rank))
    groups = await asyncio.to_thread(plant_oscillations, loops, ts)
    return [asdict(g) | {"loops": list(g.loops), "evidence": list(g.evidence)} for g in groups]


class PlantOscillationWatch(BackgroundTask):
    """Runs ``plant_pass`` every ``period_s`` and stores its groups (a failure logged once
    until a pass succeeds again)."""

    name = "plant-oscillations"

    def __init__(
        self, store: Store, schedules: Sequence[LoopSchedule], window_s: float, period_s: float
    ) -> None:
        self.store = store
        self.schedules = list(schedules)
        self.window_s = window_s
        self.period_s = period_s
        self._failing = False

    async def once(self) -> list[dict[str, Any]]:
        """One pass, stored; returns its groups."""
        groups = await plant_pass(self.store, self.schedules, self.window_s)
        await record_plant_oscillations(self.store, time.time_ns() // 1000, groups)
        return groups

    async def _run(self) -> None:
        while True:
            await asyncio.sleep(self.period_s)
            try:
                groups = await self.once()
            except Exception as exc:
                if not self._failing:
                    log.warning("plant-wide oscillation pass failed: %s (logged once)", exc)
                self._failing = True
                continue
            if self._failing:
                log.info("plant-wide oscillation pass recovered")
            self._failing = False
            log.debug("plant-wide oscillations: %d group(s)", len(groups))
