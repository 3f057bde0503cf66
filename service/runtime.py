"""One running plantcheck service: ingestion, the diagnosis scheduler and their metrics.

``Runtime.start(cfg)`` is called from the FastAPI lifespan (``service/app.py``), so the
connectors, the APScheduler instance and the API share one event loop and one process.
The API reaches the runtime only through the ``ServiceBackend`` protocol (``api/deps.py``):
it reads the store and never runs a diagnosis itself. On PostgreSQL one process per database
schedules (the holder of the scheduler lock); others stand by (``Runtime``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Literal

from plantcheck.api.deps import iso
from plantcheck.api.models import Readiness, StorageOut
from plantcheck.connectors.base import SourceHealth, now_us
from plantcheck.service.alert_rules import rules_for_loop
from plantcheck.service.alerts import AlertDispatcher
from plantcheck.service.config import Config
from plantcheck.service.ingest import HEALTH_REPORT_S, Ingestion, down_past_grace
from plantcheck.service.metrics import ServiceMetrics
from plantcheck.service.plant_oscillations import PlantOscillationWatch
from plantcheck.service.scheduler import DiagnosisScheduler, LoopSchedule
from plantcheck.storage.leader_lock import LeaderLock
from plantcheck.storage.results import loop_states
from plantcheck.storage.source_health import ReportedHealth, reported_health
from plantcheck.storage.store import Store
from plantcheck.storage.window import HELD, SIGNALS

if TYPE_CHECKING:  # procrastinate and psycopg are imported only by the queue engine
    from plantcheck.service.diagnosis_queue import QueueScheduler

log = logging.getLogger("plantcheck.runtime")


def make_scheduler(
    cfg: Config, store: Store, metrics: ServiceMetrics
) -> DiagnosisScheduler | QueueScheduler:
    """The configured engine: this process's worker pool, or the PostgreSQL job queue."""
    d = cfg.scheduler
    if d.engine == "queue":
        from plantcheck.service.diagnosis_queue import QueueScheduler

        return QueueScheduler(
            store,
            schedules_of(cfg),
            metrics,
            batch_size=d.batch_size,
            stalled_after_s=d.stalled_after_s,
        )
    return DiagnosisScheduler(
        store,
        schedules_of(cfg),
        d.workers,
        metrics,
        confirm=d.confirm,
        quantify_every_s=d.quantify_every_s,
        window_cache_mb=d.window_cache_mb,
        baseline_days=d.baseline_days,
        baseline_min=d.baseline_min,
    )


REPORT_STALE_S = 6 * HEALTH_REPORT_S
"""A source whose reader has not reported for this long is down: its collector is gone (s)."""


def remote_health(
    cfg: Config, local: set[str], reports: dict[str, ReportedHealth], now: int
) -> list[SourceHealth]:
    """The configured sources (with loops) this process does not read, as last reported: a
    report older than ``REPORT_STALE_S`` makes the source ``down`` since that report, naming
    the silent collector; a source never reported is ``unknown``."""
    used = {lp.source for lp in cfg.loop}
    out = []
    for src in cfg.source:
        if src.name in local or src.name not in used:
            continue
        who = f"collector {src.collector!r}" if src.collector else "the scheduling service"
        r = reports.get(src.name)
        if r is None:
            out.append(
                SourceHealth(
                    src.name, src.protocol, "unknown", None, None, 0, f"{who} has not reported yet"
                )
            )
            continue
        age_s = (now - r.reported_us) / 1e6
        if age_s > REPORT_STALE_S:
            out.append(
                replace(
                    r.health,
                    state="down",
                    since_us=r.reported_us,
                    last_error=f"{who} silent for {age_s:.0f} s (its last report: "
                    f"{r.health.state})",
                )
            )
        else:
            out.append(r.health)
    return out


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
            lp.stiction_limit,
            lp.dead_time_s,
            tuple(lp.controller.model_dump().items()),
            lp.description,
            lp.area,
            lp.criticality,
            rules_for_loop(cfg.alerts.rule, lp.id, lp.area, lp.criticality),
        )
        for lp in cfg.loop
    ]


Role = Literal["single", "leader", "standby"]


@dataclass
class Runtime:
    """The parts of a running service (``connect``/``schedule`` off: an API over the store).

    On PostgreSQL a scheduling runtime first takes the scheduler lock (``storage.leader_lock``):
    the holder ingests its sources and schedules the diagnosis (``role`` ``leader``); a second
    ``plantcheck run`` serves the API over the same store and stands by (``standby``), trying
    the lock every ``takeover_poll_s``, and takes both jobs over when the holder dies. A standby
    reads no source: two processes polling one device would store its values twice at
    different times. SQLite has one process: ``single``.
    """

    cfg: Config
    metrics: ServiceMetrics
    config_hint: str = ""
    connect: bool = True
    schedule: bool = True
    ingestion: Ingestion | None = None
    scheduler: DiagnosisScheduler | QueueScheduler | None = None
    role: Role = "single"
    _lock: LeaderLock | None = None
    _lock_store: Store | None = None
    plant_watch: PlantOscillationWatch | None = None
    """The plant-wide oscillation pass (while scheduling)."""
    alert_dispatcher: AlertDispatcher | None = None
    """Delivers the alert outbox (while scheduling, with alert targets configured)."""
    _watch: asyncio.Task[None] | None = None
    _reports: asyncio.Task[None] | None = None
    _remote: list[SourceHealth] = field(default_factory=list)
    """Health of the sources other processes read (collectors, the leader), from the store."""
    _stored_seen: int = 0
    _stopping: asyncio.Event = field(default_factory=asyncio.Event)

    @classmethod
    async def start(
        cls, cfg: Config, config_hint: str = "", *, connect: bool = True, schedule: bool = True
    ) -> Runtime:
        """Open the store, start the connectors and the scheduler (or stand by for them)."""
        rt = cls(cfg, ServiceMetrics(), config_hint, connect, schedule)
        if not (schedule and cfg.storage.url.startswith("postgresql")):
            await rt._lead()
            # one process per SQLite database: it schedules alone, so it leads (issue 47)
            rt.metrics.leader.set(1 if schedule else 0)
            rt._reports = asyncio.create_task(rt._read_reports(), name="health-reports")
            return rt
        rt._lock_store = await Store.open(cfg.storage.url, config_hint=config_hint)
        rt._lock = LeaderLock(rt._lock_store)
        try:
            if await rt._lock.try_acquire():
                await rt._lead()
                rt.role = "leader"
            else:
                rt.role = "standby"
                log.info(
                    "another `plantcheck run` holds the scheduler lock of this database: "
                    "standing by (serving the API; taking over when it stops)"
                )
        except BaseException:
            await rt._lock.release()
            await rt._lock_store.close()
            raise
        rt.metrics.leader.set(1 if rt.role == "leader" else 0)
        rt._watch = asyncio.create_task(rt._watch_lock(), name="scheduler-lock")
        rt._reports = asyncio.create_task(rt._read_reports(), name="health-reports")
        return rt

    async def _lead(self) -> None:
        """Start ingesting and scheduling."""
        cfg, metrics = self.cfg, self.metrics
        ing = await Ingestion.start(
            cfg, self.config_hint, on_samples=metrics.received, connect=self.connect
        )
        sched: DiagnosisScheduler | QueueScheduler | None = None
        try:
            if self.schedule:
                sched = make_scheduler(cfg, ing.store, metrics)
                await sched.start()
                d = cfg.scheduler
                self.plant_watch = PlantOscillationWatch(
                    ing.store, schedules_of(cfg), d.window_s, d.period_s
                )
                self.plant_watch.start()
                if cfg.alerts.target:
                    self.alert_dispatcher = AlertDispatcher(ing.store, cfg.alerts, metrics)
                    self.alert_dispatcher.start()
            metrics.set_loop_states(await loop_states(ing.store))
        except BaseException:
            await self._stop_plant_tasks()
            if sched is not None:
                await sched.stop()
            await ing.stop()
            raise
        self.ingestion, self.scheduler = ing, sched

    async def _stop_plant_tasks(self) -> None:
        if self.alert_dispatcher is not None:
            await self.alert_dispatcher.stop()
            self.alert_dispatcher = None
        if self.plant_watch is not None:
            await self.plant_watch.stop()
            self.plant_watch = None

    async def _step_down(self) -> None:
        await self._stop_plant_tasks()
        if self.scheduler is not None:
            await self.scheduler.stop()
        if self.ingestion is not None:
            await self.ingestion.stop()
        self.ingestion, self.scheduler = None, None

    async def _watch_lock(self) -> None:
        """Keep the lock (leader) or try to take it (standby), every ``takeover_poll_s``."""
        assert self._lock is not None and self._lock_store is not None
        lock, poll = self._lock, self.cfg.scheduler.takeover_poll_s
        waiting_since = time.monotonic()
        while True:
            await asyncio.sleep(poll)
            if lock.held and await lock.still_held():
                continue
            if await lock.try_acquire():
                if self.role == "standby":
                    try:
                        await self._lead()
                    except Exception as exc:
                        log.error("taking over as the scheduler failed: %s; retrying", exc)
                        await lock.release()
                        continue
                    log.warning(
                        "took over as the scheduler after %.1f s standing by",
                        time.monotonic() - waiting_since,
                    )
                    self.role = "leader"
                    self.metrics.leader.set(1)
            elif self.role == "leader" and await self._lock_store.ping():
                # the database answers and another process holds the lock: it leads now
                log.warning("another `plantcheck run` holds the scheduler lock: standing by")
                await self._step_down()
                self.role, waiting_since = "standby", time.monotonic()
                self.metrics.leader.set(0)

    @property
    def store(self) -> Store:
        if self.ingestion is not None:
            return self.ingestion.store
        assert self._lock_store is not None
        return self._lock_store

    @property
    def stiction_limits(self) -> dict[str, float]:
        """Per-valve stiction limit (S, % of travel) by loop id."""
        return {lp.id: lp.stiction_limit for lp in self.cfg.loop}

    @property
    def held_signals(self) -> dict[str, tuple[str, ...]]:
        """Signals that keep their value between samples, by loop id (every signal of an OPC UA
        source, which reports changes only; SP and mode otherwise)."""
        return {s.name: s.hold for s in schedules_of(self.cfg)}

    async def _read_reports(self) -> None:
        """Refresh the health of the sources this process does not read, every
        ``HEALTH_REPORT_S`` (the last known stays while the store is unreachable)."""
        while True:
            with contextlib.suppress(Exception):
                self._remote = remote_health(
                    self.cfg, self._local_names(), await reported_health(self.store), now_us()
                )
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stopping.wait(), HEALTH_REPORT_S)
            if self._stopping.is_set():
                return

    def _local_names(self) -> set[str]:
        return {c.name for c in self.ingestion.connectors} if self.ingestion else set()

    async def stop(self) -> None:
        # the reports' reader ends between two reads: cancelled within one, the database
        # driver's thread would answer a loop that has closed
        self._stopping.set()
        if self._reports is not None:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.shield(self._reports), 10.0)
        for task in (self._watch, self._reports):
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        await self._step_down()
        if self._lock is not None:
            await self._lock.release()
        if self._lock_store is not None:
            await self._lock_store.close()

    async def readiness(self) -> Readiness:
        """Storage reachable and taking this process's samples, (when scheduling) the
        scheduler running or standing by, and no source down past its grace period (those
        named)."""
        storage = await self.store.ping()
        scheduler = (
            not self.schedule
            or self.role == "standby"
            or (self.scheduler is not None and self.scheduler.running)
        )
        down = down_past_grace(self.cfg, self.sources(), now_us())
        problems = []
        if not storage:
            problems.append("storage: the database does not answer")
        writes, buffer = True, True
        if self.ingestion is not None:
            w = self.ingestion.writer
            writes, buffer = w.stats.store_up, w.stats.buffer_up
            if not writes:
                problems.append(f"storage: sample commits fail ({w.stats.store_error})")
            if not buffer:
                problems.append(
                    f"buffer: the durable buffer fails ({w.stats.buffer_error}); {w.held} "
                    f"samples held in memory, {w.dropped} dropped"
                )
        if not scheduler:
            problems.append("scheduler: not running")
        if down:
            problems.append(f"sources down past their grace period: {', '.join(down)}")
        return Readiness(
            ready=storage and writes and scheduler and not down,
            storage=storage and writes,
            scheduler=scheduler,
            sources=not down,
            sources_down=down,
            role=self.role,
            storage_writes=writes,
            buffer=buffer,
            problems=problems,
        )

    def storage_health(self) -> StorageOut:
        """This process's sample writer: database, durable buffer, memory (issue 45)."""
        if self.ingestion is None:
            return StorageOut(
                ingesting=False,
                database="up",
                database_since=None,
                database_error="",
                buffer="up",
                buffer_since=None,
                buffer_error="",
                buffer_path=self.cfg.storage.buffer_path,
                samples_in_buffer=0,
                samples_in_memory=0,
                memory_max_samples=self.cfg.storage.memory_max_samples,
                samples_dropped=0,
                samples_stored=0,
            )
        w = self.ingestion.writer
        st = w.stats
        return StorageOut(
            ingesting=True,
            database="up" if st.store_up else "down",
            database_since=iso(st.store_down_since_us),
            database_error=st.store_error,
            buffer="up" if st.buffer_up else "down",
            buffer_since=iso(st.buffer_down_since_us),
            buffer_error=st.buffer_error,
            buffer_path=str(w.buffer.path),
            samples_in_buffer=len(w.buffer),
            samples_in_memory=w.held,
            memory_max_samples=w.memory_max_samples,
            samples_dropped=w.dropped,
            samples_stored=st.stored,
        )

    def sources(self) -> list[SourceHealth]:
        """Health of every data source: those this process reads, then the others as their
        collector (or the scheduling process) last reported them."""
        local = self.ingestion.source_health() if self.ingestion else []
        names = {h.name for h in local}
        return local + [h for h in self._remote if h.name not in names]

    async def diagnose_now(self, loop_id: str) -> str | None:
        """Run a loop's scheduled job now (for ``POST /loops/{id}/diagnose``)."""
        if self.scheduler is None or loop_id not in self.scheduler.schedules:
            return None
        return await self.scheduler.run_loop(loop_id)

    def metrics_text(self) -> bytes:
        """Refresh the gauges read from the writer, then render the Prometheus text."""
        m = self.metrics
        if self.ingestion is not None:
            w = self.ingestion.writer
            stored = w.stats.stored
            if stored > self._stored_seen:
                m.samples_stored.inc(stored - self._stored_seen)
                self._stored_seen = stored
            m.buffer_depth.set(w.backlog)
            m.set_sources(self.ingestion.source_health())
            m.set_store(w.stats.store_up, w.stats.store_failures)
            m.set_buffer(w.stats.buffer_up, w.held, w.dropped)
        m.sample_rate()
        return m.render()
