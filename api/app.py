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

from fastapi import FastAPI, Request
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from swagger_ui_bundle import swagger_ui_path

from plantcheck import __version__
from plantcheck.api import health, health_reports, plant, reports, routes, web
from plantcheck.api.gate import AccessSettings, HeavyReadGate, ReadKeyGate
from plantcheck.api.loop_table import LoopTable
from plantcheck.storage.errors import store_outage_errors

Lifespan = Callable[[FastAPI], AbstractAsyncContextManager[None]]

DESCRIPTION = """On-line monitoring and diagnosis of control loops (stiction, tuning,
disturbances). Times are ISO 8601 UTC. Lists are JSON arrays paginated with `limit`/`offset`
(total in `X-Total-Count`, next page in `Link`). Errors are `{"detail": ...}`. When the
configuration sets `api.require_key_for_reads`, every request needs the `X-API-Key` header;
requests that change anything always do."""

HEAVY_READS = 2
"""Sample pages served at once (``gate.HeavyReadGate``); one takes ~50 ms."""


def create_app(api_config: AccessSettings, lifespan: Lifespan) -> FastAPI:
    """The app with every route; ``lifespan`` starts and stops what serves it."""

    app = FastAPI(
        title="plantcheck",
        version=__version__,
        description=DESCRIPTION,
        lifespan=lifespan,
        # the interactive docs from this service's own files (a plant network has no internet):
        # Swagger UI from the swagger-ui-bundle package; ReDoc has no such package, so none
        docs_url=None,
        redoc_url=None,
    )
    app.state.api_config = api_config
    app.state.started = time.time()
    app.state.loop_table = LoopTable()
    app.add_middleware(HeavyReadGate, at_once=HEAVY_READS)
    app.add_middleware(ReadKeyGate, settings=api_config)  # the outermost: refuses first
    app.include_router(routes.router)
    app.include_router(reports.router)
    app.include_router(plant.router)
    app.include_router(health_reports.router)
    app.include_router(health.router)
    app.include_router(web.router)
    app.mount("/static", StaticFiles(directory=Path(__file__).parent / "static"), name="static")
    app.mount("/docs-assets", StaticFiles(directory=swagger_ui_path), name="docs-assets")

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        """Swagger UI, every asset served here; links root-relative, never from Host."""
        root = request.scope.get("root_path", "")
        return get_swagger_ui_html(
            openapi_url=f"{root}/openapi.json",
            title="plantcheck API",
            swagger_js_url=f"{root}/docs-assets/swagger-ui-bundle.js",
            swagger_css_url=f"{root}/docs-assets/swagger-ui.css",
            swagger_favicon_url=f"{root}/docs-assets/favicon-32x32.png",
        )

    for exc_type in store_outage_errors():
        app.add_exception_handler(exc_type, _store_unavailable)
    return app


RETRY_AFTER_S = 30
"""Seconds a client should wait before retrying while the store is unreachable."""


async def _store_unavailable(request: Request, exc: Exception) -> JSONResponse:
    """The database is unreachable: 503 with Retry-After, not a 500 and a traceback (issue 27).
    The samples keep going to the durable buffer meanwhile."""
    return JSONResponse(
        {"detail": f"the store is unreachable ({type(exc).__name__}); retry in a moment"},
        status_code=503,
        headers={"Retry-After": str(RETRY_AFTER_S)},
    )
