"""``require_key_for_reads`` covers every route but the probes (issue 45): each path of the
OpenAPI document, the document itself, ``/docs`` and its assets, ``/static`` and the pages answer
401 without the key and serve with it; ``/metrics`` follows its own setting. The app over a real
SQLite store, through its ASGI interface."""

from __future__ import annotations

import asyncio
import re
from pathlib import Path
from typing import Any

import httpx
import pytest
from test_samples_hourly import _config

from plantcheck.service.app import build_app
from plantcheck.service.config import Config
from plantcheck.storage.database import upgrade

# an app stopped right after it started must not leave a database call answering a closed
# event loop (the writer's housekeeping was cancelled inside a query)
pytestmark = pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")

KEY = "a-long-secret"
PROBES = {"/healthz", "/readyz"}
NOT_IN_SCHEMA = ["/openapi.json", "/docs", "/docs-assets/swagger-ui.css", "/static/app.js", "/",
                 "/loop/FIC1", "/actions", "/stiction"]  # fmt: skip


def _app_config(tmp_path: Path, **api: Any) -> Config:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    cfg = _config(url)
    return cfg.model_copy(update={"api": cfg.api.model_validate({**api})})


async def _statuses(cfg: Config, paths: list[str], key: str | None) -> dict[str, int]:
    app = build_app(cfg, connect=False, schedule=False)
    headers = {"X-API-Key": key} if key else {}
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://app") as client:
            return {p: (await client.get(p, headers=headers)).status_code for p in paths}


def _get_paths(cfg: Config) -> list[str]:
    """Every GET path of the OpenAPI document, with FIC1 for each path parameter."""
    app = build_app(cfg, connect=False, schedule=False)
    doc = app.openapi()
    return [
        re.sub(r"\{[^}]+\}", "FIC1", p) for p, ops in doc["paths"].items() if "get" in ops
    ] + NOT_IN_SCHEMA


def test_every_read_needs_the_key_but_the_probes(tmp_path: Path) -> None:
    cfg = _app_config(tmp_path, api_key=KEY, require_key_for_reads=True)
    paths = _get_paths(cfg)
    assert {"/api/v1/loops", "/api/v1/storage", "/metrics", *PROBES} <= set(paths)
    without = asyncio.run(_statuses(cfg, paths, None))
    refused = {p for p, code in without.items() if code == 401}
    # /metrics on a loopback host is open by default: its own setting
    assert set(paths) - refused == {*PROBES, "/metrics"}, without
    with_key = asyncio.run(_statuses(cfg, paths, KEY))
    assert not [p for p, code in with_key.items() if code in (401, 403) or code >= 500], with_key
    wrong = asyncio.run(_statuses(cfg, ["/api/v1/loops", "/docs"], "not-the-key"))
    assert asyncio.run(_statuses(cfg, ["/redoc"], KEY))["/redoc"] == 404  # no CDN page
    assert set(wrong.values()) == {401}


@pytest.mark.parametrize(
    ("api", "without", "with_key"),
    [
        ({}, 200, 200),  # loopback host, auto: open
        ({"metrics": "key", "api_key": KEY}, 401, 200),
        ({"metrics": "off"}, 404, 404),
        ({"host": "0.0.0.0", "api_key": KEY}, 401, 200),  # exposed, auto: the key
        ({"host": "0.0.0.0", "allow_unauthenticated": True}, 404, 404),  # exposed, no key: off
    ],
)
def test_metrics_follow_their_own_setting(
    tmp_path: Path, api: dict[str, Any], without: int, with_key: int
) -> None:
    cfg = _app_config(tmp_path, **api)
    assert asyncio.run(_statuses(cfg, ["/metrics"], None))["/metrics"] == without
    assert asyncio.run(_statuses(cfg, ["/metrics"], KEY))["/metrics"] == with_key
