"""One running plantcheck service: ingestion, the diagnosis scheduler and their metrics.

``Runtime.start(cfg)`` is called from the FastAPI lifespan (``service/app.py``), so the
connectors, the APScheduler instance and the API share one event loop and one process.
The API reaches the runtime only through the ``ServiceBackend`` protocol (``api/deps.py``):
it reads the store and never runs a diagnosis itself.
"""

from __future__ import annotations

from dataclasses import dataclass

from plantcheck.api.models import Readiness
from plantcheck.connectors.base import SourceHealth, now_us
from plantcheck.service.config import Config
from plantcheck.service.ingest import Ingestion
from plantcheck.service.metrics import ServiceMetrics
from plantcheck.service.scheduler import DiagnosisScheduler, LoopSchedule
from plantcheck.storage.results import loop_states
from plantcheck.storage.store import Store
from plantcheck.storage.window import HELD, SIGNALS


def schedules_of(cfg: Config) -> list[LoopSchedule]:
    """Each configured loop's window and period (its own, else the scheduler defaults)."""
    d = cfg.scheduler
    change_only = {s.name for s in cfg.source if s.protocol == "opcua"}
    return [
        LoopSchedule(
            lp.id,
            lp.type,
            lp.window_s or d.window_s,
            lp.period_s or d.period_s,
            SIGNALS if lp.source in change_only else HELD,
        )
        for lp in cfg.loop
    ]


@dataclass
class Runtime:
    """The parts of a running service (``connect``/``schedule`` off: an API over the store)."""

    cfg: Config
    ingestion: Ingestion
    scheduler: DiagnosisScheduler | None
    metrics: ServiceMetrics
    _stored_seen: int = 0

    @classmethod
    async def start(
        cls, cfg: Config, config_hint: str = "", *, connect: bool = True, schedule: bool = True
    ) -> Runtime:
        """Open the store, start the connectors and the scheduler."""
        metrics = ServiceMetrics()
        ing = await Ingestion.start(cfg, config_hint, on_samples=metrics.received, connect=connect)
        sched = None
        try:
            if schedule:
                sched = DiagnosisScheduler(
                    ing.store,
                    schedules_of(cfg),
                    cfg.scheduler.workers,
                    metrics,
                    confirm=cfg.scheduler.confirm,
                    quantify_every_s=cfg.scheduler.quantify_every_s,
                    window_cache_mb=cfg.scheduler.window_cache_mb,
                )
                await sched.start()
            metrics.set_loop_states(await loop_states(ing.store))
        except BaseException:
            await ing.stop()
            raise
        return cls(cfg, ing, sched, metrics)

    @property
    def store(self) -> Store:
        return self.ingestion.store

    @property
    def stiction_limits(self) -> dict[str, float]:
        """Per-valve stiction limit (S, % of travel) by loop id."""
        return {lp.id: lp.stiction_limit for lp in self.cfg.loop}

    @property
    def held_signals(self) -> dict[str, tuple[str, ...]]:
        """Signals that keep their value between samples, by loop id (every signal of an OPC UA
        source, which reports changes only; SP and mode otherwise)."""
        return {s.name: s.hold for s in schedules_of(self.cfg)}

    async def stop(self) -> None:
        if self.scheduler is not None:
            await self.scheduler.stop()
        await self.ingestion.stop()

    async def readiness(self) -> Readiness:
        """Storage reachable, (when scheduling) the scheduler running, and no source down
        past its grace period (those named)."""
        storage = await self.store.ping()
        scheduler = self.scheduler is None or self.scheduler.running
        down = self.ingestion.sources_down_past_grace(now_us())
        return Readiness(
            ready=storage and scheduler and not down,
            storage=storage,
            scheduler=scheduler,
            sources=not down,
            sources_down=down,
        )

    def sources(self) -> list[SourceHealth]:
        """Health of every data source."""
        return self.ingestion.source_health()

    async def diagnose_now(self, loop_id: str) -> str | None:
        """Run a loop's scheduled job now (for ``POST /loops/{id}/diagnose``)."""
        if self.scheduler is None or loop_id not in self.scheduler.schedules:
            return None
        return await self.scheduler.run_loop(loop_id)

    def metrics_text(self) -> bytes:
        """Refresh the gauges read from the writer, then render the Prometheus text."""
        m, w = self.metrics, self.ingestion.writer
        stored = w.stats.stored
        if stored > self._stored_seen:
            m.samples_stored.inc(stored - self._stored_seen)
            self._stored_seen = stored
        m.buffer_depth.set(w.depth)
        m.sample_rate()
        m.set_sources(self.ingestion.source_health())
        m.set_store(w.stats.store_up, w.stats.store_failures)
        return m.render()
