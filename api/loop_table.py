"""The loop-health table as the API serves it, rebuilt about once a second.

Operators' pages and dashboards poll ``GET /api/v1/loops`` all the time while verdicts change
at most once per diagnosis period; one store query per second serves any number of readers.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from typing import Any, Literal

from plantcheck.api.deps import iso
from plantcheck.storage.results import LoopStatus, loop_statuses
from plantcheck.storage.store import Store

log = logging.getLogger("plantcheck.api")


def loop_json(s: LoopStatus) -> dict[str, Any]:
    """One row of ``GET /api/v1/loops`` (the ``LoopOut`` model)."""
    return {
        "id": s.id,
        "type": s.type,
        "source": s.source,
        "description": s.description,
        "state": s.state,
        "cause": s.cause,
        "since": iso(s.since_us),
        "last_diagnosis_at": iso(s.last_diagnosis_us),
        "S": s.S,
        "J": s.J,
        "S_method": s.S_method,
        "S_at": iso(s.S_at_us),
        "priority": s.priority,
        "criticality": s.criticality,
        "area": s.area,
        "unit": s.unit,
        "kpis": s.kpis,
    }


LoopSort = Literal["id", "priority"]
"""The loop table's orders: by loop id, or the worst loops first."""


def select_loops(
    rows: list[dict[str, Any]],
    *,
    state: str | None = None,
    cause: str | None = None,
    loop_type: str | None = None,
    area: str | None = None,
    unit: str | None = None,
    sort: LoopSort = "id",
) -> list[dict[str, Any]]:
    """The rows (``loop_json``, in id order) that pass every filter given, in ``sort`` order:
    ``priority`` puts the highest priority first (ties by id). ``rows`` itself when nothing
    is filtered or reordered."""
    wanted = {"state": state, "cause": cause, "type": loop_type, "area": area, "unit": unit}
    wanted = {k: v for k, v in wanted.items() if v is not None}
    selected = [r for r in rows if all(r[k] == v for k, v in wanted.items())] if wanted else rows
    if sort == "priority":
        selected = sorted(selected, key=lambda r: -r["priority"])  # stable: ties stay by id
    return selected


class LoopTable:
    """Cached rows and JSON body of the whole table, ``ttl_s`` seconds old at most once warm.

    A reader of a table older than ``ttl_s`` waits for one shared refresh (at most
    ``wait_s``; a store that does not answer in that time gets the table as last read, so the
    page never hangs on an outage): what a poller sees is never one request old (issue 47). A
    refresh reads only the loops diagnosed
    since the last one (with ``margin_s`` for the clocks of workers on other machines) and keeps
    each row's JSON, so at 10,000 loops it costs a few milliseconds of the event loop instead of
    the 150-250 ms a whole rebuild takes; the whole table is still read every ``full_every_s``
    (a loop's description or type changed by a configuration, an estimate stored late).
    """

    def __init__(
        self,
        ttl_s: float = 0.5,
        full_every_s: float = 300.0,
        margin_s: float = 2.0,
        wait_s: float = 2.0,
    ) -> None:
        self.ttl_s = ttl_s
        self.wait_s = wait_s
        self.full_every_s = full_every_s
        self.margin_us = int(margin_s * 1e6)
        self._at = -float("inf")
        self._full_at = -float("inf")
        self._rows: list[dict[str, Any]] = []
        self._body = b"[]"
        self._by_id: dict[str, tuple[dict[str, Any], bytes]] = {}
        self._newest_us: int | None = None
        self._lock = asyncio.Lock()
        self._refresh: asyncio.Task[None] | None = None
        self._failing = False
        """The last background refresh failed (logged once per outage)."""

    def _refreshed(self, task: asyncio.Task[None]) -> None:
        """A background refresh ended: its failure is logged once per outage, and the return
        once (never "exception was never retrieved" per request)."""
        if task.cancelled():
            return
        exc = task.exception()
        if exc is None:
            if self._failing:
                log.warning("loop table: the store answers again; the table is current")
            self._failing = False
        elif not self._failing:
            self._failing = True
            log.error(
                "loop table: cannot refresh from the store (%s: %s); serving the table as "
                "last read until it answers",
                type(exc).__name__,
                str(exc).splitlines()[0] if str(exc) else "",
            )

    async def _build(self, store: Store) -> None:
        now = time.monotonic()
        full = now - self._full_at >= self.full_every_s or self._newest_us is None
        since = None if full else self._newest_us - self.margin_us  # type: ignore[operator]
        statuses = await loop_statuses(store, diagnosed_since_us=since)
        by_id = {} if full else dict(self._by_id)
        for i, st in enumerate(statuses):
            if i % 500 == 499:
                await asyncio.sleep(0)  # a whole rebuild lets the requests waiting go first
            row = loop_json(st)
            by_id[st.id] = (row, json.dumps(row, separators=(",", ":")).encode())
            if st.last_diagnosis_us is not None:
                self._newest_us = max(self._newest_us or 0, st.last_diagnosis_us)
        if full:
            self._full_at = now
            self._newest_us = self._newest_us or 0
        if full or statuses:
            ordered = [by_id[k] for k in sorted(by_id)]
            self._by_id = by_id
            self._rows = [row for row, _ in ordered]
            self._body = b"[" + b",".join(frag for _, frag in ordered) + b"]"
        self._at = now

    async def close(self, timeout_s: float = 5.0) -> None:
        """End a background refresh before the store it reads is closed (a refresh left
        running would touch a closed connection from a finished event loop)."""
        task, self._refresh = self._refresh, None
        if task is None or task.done():
            return
        # on a time-out wait_for cancels it; its failure was logged by _refreshed
        with contextlib.suppress(Exception):
            await asyncio.wait_for(task, timeout_s)

    async def get(self, store: Store) -> tuple[list[dict[str, Any]], bytes]:
        """(rows, their JSON array), refreshed from the store when older than ``ttl_s``."""
        if self._at == -float("inf"):
            async with self._lock:
                if self._at == -float("inf"):
                    await self._build(store)
        elif time.monotonic() - self._at >= self.ttl_s:
            if self._refresh is None or self._refresh.done():
                self._refresh = asyncio.create_task(self._build(store))
                self._refresh.add_done_callback(self._refreshed)
            # shielded: a reader that gives up does not cancel the refresh the others share
            with contextlib.suppress(Exception):
                await asyncio.wait_for(asyncio.shield(self._refresh), self.wait_s)
        return self._rows, self._body
