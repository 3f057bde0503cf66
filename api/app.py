"""The FastAPI application: REST API (``/api/v1``), probes, metrics and the web page.

``create_app`` builds the app around any lifespan that puts a ``ServiceBackend`` on
``app.state.backend`` (``service/app.py`` starts the real service there). The API reads the store
and never computes a diagnosis.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager
from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from plantcheck import __version__
from plantcheck.api import health, reports, routes, web
from plantcheck.api.loop_table import LoopTable
from plantcheck.service.config import ApiConfig

Lifespan = Callable[[FastAPI], AbstractAsyncContextManager[None]]

DESCRIPTION = """On-line monitoring and diagnosis of control loops (stiction, tuning,
disturbances). Times are ISO 8601 UTC. Lists are JSON arrays paginated with `limit`/`offset`
(total in `X-Total-Count`, next page in `Link`). Errors are `{"detail": ...}`. When the
configuration sets `api.require_key_for_reads`, every request needs the `X-API-Key` header;
requests that change anything always do."""


def create_app(api_config: ApiConfig, lifespan: Lifespan) -> FastAPI:
    """The app with every route; ``lifespan`` starts and stops what serves it."""

    app = FastAPI(
        title="plantcheck",
        version=__version__,
        description=DESCRIPTION,
        lifespan=lifespan,
    )
    app.state.api_config = api_config
    app.state.started = time.time()
    app.state.loop_table = LoopTable()
    app.include_router(routes.router)
    app.include_router(reports.router)
    app.include_router(health.router)
    app.include_router(web.router)
    app.mount("/static", StaticFiles(directory=Path(__file__).parent / "static"), name="static")
    return app
