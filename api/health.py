"""Liveness, readiness and Prometheus metrics (no ``/api/v1`` prefix, no API key: probes and
scrapers run inside the plant network; bind the service to loopback or firewall it)."""

from __future__ import annotations

import time

from fastapi import APIRouter, Request, Response
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST

from plantcheck import __version__
from plantcheck.api.deps import Backend
from plantcheck.api.models import Health, Readiness

router = APIRouter()


@router.get("/healthz", response_model=Health)
async def healthz(request: Request) -> Health:
    """Liveness: the process answers."""
    return Health(version=__version__, uptime_s=round(time.time() - request.app.state.started, 1))


@router.get(
    "/readyz",
    response_model=Readiness,
    responses={503: {"model": Readiness, "description": "Storage, scheduler or a source down"}},
)
async def readyz(backend: Backend) -> Response:
    """Readiness: the store answers, the scheduler runs and no source has been down past its
    grace period (503 otherwise)."""
    body = await backend.readiness()
    return JSONResponse(body.model_dump(), status_code=200 if body.ready else 503)


@router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text"}},
)
async def metrics(backend: Backend) -> Response:
    """Prometheus text format: samples/s, buffer depth, diagnosis duration, loops per state."""
    return Response(backend.metrics_text(), media_type=CONTENT_TYPE_LATEST)
