"""The service application: the FastAPI app whose lifespan runs the whole service.

Starting the app starts the store, the sample writer, the connectors and one APScheduler
``AsyncIOScheduler`` (one scheduler per deployment: run a single ``plantcheck run`` process per
database); stopping it stops them in reverse order, flushing every received sample.
"""

from __future__ import annotations

import gc
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from plantcheck.api.app import create_app
from plantcheck.service.config import Config
from plantcheck.service.runtime import Runtime


def build_app(
    cfg: Config, config_hint: str = "", *, connect: bool = True, schedule: bool = True
) -> FastAPI:
    """The app for ``cfg``; ``connect``/``schedule`` off serve the store as it is."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        runtime = await Runtime.start(cfg, config_hint, connect=connect, schedule=schedule)
        app.state.backend = runtime
        # what start-up made (modules, the configuration, the scheduler) lives as long as the
        # process: out of the collector's sight, a full collection under load takes a few ms
        # instead of ~100 (the pause /healthz would show)
        gc.freeze()
        try:
            yield
        finally:
            app.state.backend = None
            await app.state.loop_table.close()
            await runtime.stop()

    return create_app(cfg.api, lifespan)
