"""The heavy reads' turn: pages of up to 10,000 samples are served a few at a time (issue 45).

A pure ASGI middleware, so that a request waiting for its turn has cost nothing but its
arrival: 200 sample pages asked at once neither hold 200 pages in memory nor keep ``/healthz``
waiting behind 200 requests' routing and validation.
"""

from __future__ import annotations

import asyncio
import re
from typing import Any

HEAVY_PATH = re.compile(r"^/api/v1/loops/[^/]+/samples$")
"""The routes whose one request may read 10,000 rows per signal."""


class HeavyReadGate:
    """At most ``at_once`` heavy reads in progress; the others wait, in arrival order."""

    def __init__(self, app: Any, at_once: int = 2) -> None:
        self.app = app
        self.turns = asyncio.Semaphore(at_once)

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] == "http" and HEAVY_PATH.match(scope.get("path", "")):
            async with self.turns:
                await self.app(scope, receive, send)
            return
        await self.app(scope, receive, send)
