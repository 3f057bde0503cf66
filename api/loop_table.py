"""The loop-health table as the API serves it, rebuilt about once a second.

Operators' pages and dashboards poll ``GET /api/v1/loops`` all the time while verdicts change
at most once per diagnosis period; one store query per second serves any number of readers.
"""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

from plantcheck.api.deps import iso
from plantcheck.storage.results import LoopStatus, loop_statuses
from plantcheck.storage.store import Store


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
    }


class LoopTable:
    """Cached rows and JSON body of the whole table, ``ttl_s`` seconds old at most once warm.

    Stale-while-revalidate: after the first build a reader never waits for the store; a stale
    table is served while one background refresh runs.
    """

    def __init__(self, ttl_s: float = 1.0) -> None:
        self.ttl_s = ttl_s
        self._at = -float("inf")
        self._rows: list[dict[str, Any]] = []
        self._body = b"[]"
        self._lock = asyncio.Lock()
        self._refresh: asyncio.Task[None] | None = None

    async def _build(self, store: Store) -> None:
        rows = [loop_json(s) for s in await loop_statuses(store)]
        self._rows, self._body = rows, json.dumps(rows, separators=(",", ":")).encode()
        self._at = time.monotonic()

    async def get(self, store: Store) -> tuple[list[dict[str, Any]], bytes]:
        """(rows, their JSON array), refreshed from the store when older than ``ttl_s``."""
        if self._at == -float("inf"):
            async with self._lock:
                if self._at == -float("inf"):
                    await self._build(store)
        elif time.monotonic() - self._at >= self.ttl_s and (
            self._refresh is None or self._refresh.done()
        ):
            self._refresh = asyncio.create_task(self._build(store))
        return self._rows, self._body
