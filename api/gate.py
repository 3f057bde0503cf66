"""Gates in front of every route, as pure ASGI middleware (issue 45).

``ReadKeyGate``: with ``require_key_for_reads`` every request needs the key, whatever serves it
(the routes, the OpenAPI document, ``/docs`` and its assets, ``/static``), except the probes
``/healthz`` and ``/readyz``; ``/metrics`` follows its own setting (``metrics_access``: open,
key, off), since its labels name every loop and its state.

``HeavyReadGate``: pages of up to 10,000 samples are served a few at a time, so that a request
waiting for its turn has cost nothing but its arrival: 200 sample pages asked at once neither
hold 200 pages in memory nor keep ``/healthz`` waiting behind 200 requests' routing.
"""

from __future__ import annotations

import asyncio
import json
import re
import secrets
from typing import Any, Literal, Protocol

PROBES = frozenset({"/healthz", "/readyz"})
"""Open whatever the settings: orchestrators and load balancers probe without a key."""


class AccessSettings(Protocol):
    """The ``[api]`` settings the key gate and the routes' key checks read."""

    @property
    def api_key(self) -> str: ...
    @property
    def require_key_for_reads(self) -> bool: ...
    @property
    def metrics_access(self) -> Literal["open", "key", "off"]: ...


def key_matches(given: str | None, expected: str) -> bool:
    """Constant-time comparison; an empty key (given or configured) never matches."""
    if not given or not expected:
        return False
    return secrets.compare_digest(given.encode(), expected.encode())


async def _refuse(send: Any, status: int, detail: str) -> None:
    body = json.dumps({"detail": detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    if status == 401:
        headers.append((b"www-authenticate", b"X-API-Key"))
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class ReadKeyGate:
    """Refuses, before any route runs, what needs the key and does not carry it."""

    def __init__(self, app: Any, settings: AccessSettings) -> None:
        self.app = app
        self.settings = settings

    def _given(self, scope: dict[str, Any]) -> str | None:
        for name, value in scope.get("headers", ()):
            if name == b"x-api-key":
                return str(value.decode("latin-1"))
        return None

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        path, cfg = scope.get("path", ""), self.settings
        if path == "/metrics":
            if cfg.metrics_access == "off":
                await _refuse(send, 404, "metrics are off: set [api] metrics = 'key' or 'open'")
                return
            needed = cfg.metrics_access == "key"
        else:
            needed = cfg.require_key_for_reads and path not in PROBES
        if needed and not key_matches(self._given(scope), cfg.api_key):
            await _refuse(
                send, 401, "missing or wrong X-API-Key header (reads require the API key)"
            )
            return
        await self.app(scope, receive, send)


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
