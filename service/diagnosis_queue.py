"""Diagnosis on a PostgreSQL job queue: procrastinate 3.10 (issue 28).

With ``[scheduler] engine = "queue"`` the one scheduling ``plantcheck run`` (the holder of the
scheduler lock, ``storage.leader_lock``) does not diagnose: every period it enqueues one job per
batch of loops (``batch_size``, loops of equal period together), and ``plantcheck worker``
processes on any number of machines run them: read each loop's window, diagnose it in their
process pool, store the verdict. PostgreSQL is the only shared part.

- A batch's job carries the batch as its ``lock`` (two jobs of one batch never run at the same
  time, so a window is never diagnosed twice at once) and as its ``queueing_lock`` (a batch
  still waiting when its next period comes is not queued twice: counted in
  ``plantcheck_queue_jobs_skipped_total``, a sign the workers do not keep up).
- A worker that dies stops sending heartbeats; after ``stalled_after_s`` the scheduler hands its
  running jobs back to the queue for another worker (``plantcheck_queue_jobs_recovered_total``),
  or drops one whose batch is already queued again.
- Queue depth by job status and the time from enqueueing to the end of each job are Prometheus
  metrics of the scheduling service (read from procrastinate's tables every few seconds).
- The workers keep no loop state of their own that matters: the confirmation streak and the
  quantification schedule come from the stored history (``DiagnosisScheduler.
  adopt_shared_history``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import time
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import procrastinate
from apscheduler.schedulers.asyncio import AsyncIOScheduler
from procrastinate import exceptions as queue_errors
from procrastinate.jobs import Status

from plantcheck.service.metrics import ServiceMetrics
from plantcheck.service.scheduler import DiagnosisScheduler, LoopSchedule
from plantcheck.storage.results import loop_statuses
from plantcheck.storage.store import Store

log = logging.getLogger("plantcheck.queue")

QUEUE = "plantcheck_diagnosis"
TASK = "plantcheck.diagnose_batch"


def queue_conninfo(url: str) -> str:
    """psycopg's connection string from the store's SQLAlchemy URL (same server and user)."""
    return "postgresql://" + url.split("://", 1)[1]


def queue_app(url: str, max_size: int = 4) -> procrastinate.App:
    """A procrastinate app on the store's PostgreSQL database (opened by the caller)."""
    connector = procrastinate.PsycopgConnector(
        conninfo=queue_conninfo(url), min_size=1, max_size=max_size
    )
    return procrastinate.App(connector=connector)


async def ensure_queue_schema(app: procrastinate.App) -> bool:
    """Create procrastinate's tables when absent; True when this call created them.

    Two processes starting together may both find them absent: the loser's error is ignored
    once the tables are there."""
    present = "SELECT to_regclass('procrastinate_jobs') IS NOT NULL AS present"
    if (await app.connector.execute_query_one_async(present))["present"]:
        return False
    try:
        await app.schema_manager.apply_schema_async()
    except Exception:
        if not (await app.connector.execute_query_one_async(present))["present"]:
            raise
        return False
    log.info("job queue tables created (procrastinate %s)", procrastinate.__version__)
    return True


@dataclass(frozen=True)
class Batch:
    """Loops diagnosed by one job, every ``period_s``."""

    key: str
    loops: tuple[str, ...]
    period_s: float


def batches_of(schedules: Sequence[LoopSchedule], size: int) -> list[Batch]:
    """Loops of equal period in batches of at most ``size``, named by period and index."""
    by_period: dict[float, list[str]] = defaultdict(list)
    for s in schedules:
        by_period[s.period_s].append(s.name)
    out = []
    for period, names in sorted(by_period.items()):
        for i in range(0, len(names), size):
            out.append(
                Batch(f"diagnose:{period:g}s:{i // size}", tuple(names[i : i + size]), period)
            )
    return out


_DEPTH = f"""SELECT status::text AS status, count(*) AS n FROM procrastinate_jobs
WHERE queue_name = '{QUEUE}' GROUP BY status"""

_FINISHED = f"""SELECT j.id, EXTRACT(EPOCH FROM max(e.at) - min(e.at))::float AS seconds
FROM procrastinate_jobs j JOIN procrastinate_events e ON e.job_id = j.id
WHERE j.queue_name = '{QUEUE}' AND j.status IN ('succeeded', 'failed') AND j.id > %(after)s
GROUP BY j.id ORDER BY j.id"""


class QueueScheduler:
    """The scheduling side: enqueue the batches, recover stalled jobs, publish queue metrics.

    Same face as ``DiagnosisScheduler`` towards the runtime (``start``, ``stop``, ``running``,
    ``run_loop``, ``schedules``)."""

    def __init__(
        self,
        store: Store,
        schedules: list[LoopSchedule],
        metrics: ServiceMetrics,
        *,
        batch_size: int = 100,
        stalled_after_s: float = 30.0,
        first_run_within_s: float = 30.0,
    ) -> None:
        self.store = store
        self.schedules = {s.name: s for s in schedules}
        self.batches = batches_of(schedules, batch_size)
        self._batch_of = {n: b for b in self.batches for n in b.loops}
        self.metrics = metrics
        self.stalled_after_s = stalled_after_s
        self.first_run_within_s = first_run_within_s
        self.app = queue_app(str(store.engine.url.render_as_string(hide_password=False)))
        self._scheduler: Any = None
        self._finished_after = 0
        self._watch_failing = False
        self._queue_failing = False
        self._behind: set[str] = set()
        """Batches whose last job still waited at their next period (logged once)."""

    @property
    def running(self) -> bool:
        return self._scheduler is not None and bool(self._scheduler.running)

    async def start(self) -> None:
        await self.app.open_async()
        await ensure_queue_schema(self.app)
        self._finished_after = await self._newest_finished_id()
        self._scheduler = AsyncIOScheduler(timezone="UTC")
        now, n = time.time(), max(1, len(self.batches))
        for i, b in enumerate(self.batches):
            first = now + 1.0 + min(self.first_run_within_s, b.period_s) * i / n
            self._scheduler.add_job(
                self.enqueue,
                "interval",
                seconds=b.period_s,
                args=[b],
                id=b.key,
                next_run_time=datetime.fromtimestamp(first, UTC),
                max_instances=1,
                coalesce=True,
                misfire_grace_time=max(1, int(b.period_s)),
            )
        watch_s = max(1.0, min(5.0, self.stalled_after_s / 3))
        self._scheduler.add_job(self.watch, "interval", seconds=watch_s, id="queue-watch")
        self._scheduler.add_job(self.purge, "interval", hours=1, id="queue-purge")
        self._scheduler.start()
        log.info(
            "diagnosis of %d loops queued in %d batches for `plantcheck worker` processes",
            len(self.schedules),
            len(self.batches),
        )

    async def stop(self, drain_s: float = 10.0) -> None:
        if self._scheduler is not None and self._scheduler.running:
            self._scheduler.shutdown(wait=False)
        with contextlib.suppress(Exception):
            await self.app.close_async()

    async def enqueue(self, batch: Batch, loops: Sequence[str] | None = None) -> int | None:
        """Queue a job for ``batch`` (or some of its loops); the job id, or None when the batch
        is still waiting from its last period or the queue cannot be reached."""
        names: list[Any] = list(loops or batch.loops)
        deferrer = self.app.configure_task(
            TASK, queue=QUEUE, lock=batch.key, queueing_lock=None if loops else batch.key
        )
        try:
            job_id = await deferrer.defer_async(loops=names, enqueued_us=time.time_ns() // 1000)
        except queue_errors.AlreadyEnqueued:
            self.metrics.queue_jobs_skipped.inc()
            if batch.key not in self._behind:
                log.warning(
                    "%s still waits from its last period: the workers do not keep up (start "
                    "workers, add some, or lengthen period_s; logged once until it recovers)",
                    batch.key,
                )
            self._behind.add(batch.key)
            return None
        except Exception as exc:
            if not self._queue_failing:
                log.warning(
                    "queueing %s failed: %s (logged once until it recovers)", batch.key, exc
                )
            self._queue_failing = True
            return None
        if self._queue_failing:
            log.info("queueing jobs recovered")
            self._queue_failing = False
        if loops is None and batch.key in self._behind:
            self._behind.discard(batch.key)
            log.info("%s queued on time again", batch.key)
        return int(job_id)

    async def watch(self) -> None:
        """Hand stalled jobs to live workers and refresh the queue metrics (logged once while
        it fails)."""
        try:
            await self.recover_stalled()
            await self._refresh_metrics()
        except Exception as exc:
            if not self._watch_failing:
                log.warning("watching the job queue failed: %s (logged once)", exc)
            self._watch_failing = True
            return
        if self._watch_failing:
            log.info("watching the job queue recovered")
        self._watch_failing = False

    async def recover_stalled(self) -> int:
        """Jobs of workers silent for ``stalled_after_s``: back to the queue (another worker
        runs them), or ended when their batch is already queued again."""
        jm = self.app.job_manager
        stalled = await jm.get_stalled_jobs(
            queue=QUEUE, seconds_since_heartbeat=self.stalled_after_s
        )
        n = 0
        for job in stalled:
            try:
                await jm.retry_job(job)
                log.warning("job %s (%s) of a dead worker queued again", job.id, job.lock)
            except queue_errors.ConnectorException:  # its batch is queued already
                await jm.finish_job(job, Status.FAILED, delete_job=False)
                log.warning("job %s (%s) of a dead worker dropped: queued again", job.id, job.lock)
            self.metrics.queue_jobs_recovered.inc()
            n += 1
        return n

    async def purge(self) -> None:
        """Finished jobs older than an hour leave the queue's tables."""
        with contextlib.suppress(Exception):
            await self.app.job_manager.delete_old_jobs(nb_hours=1, queue=QUEUE, include_failed=True)

    async def _newest_finished_id(self) -> int:
        row = await self.app.connector.execute_query_one_async(
            f"SELECT coalesce(max(id), 0) AS id FROM procrastinate_jobs WHERE queue_name = "
            f"'{QUEUE}' AND status IN ('succeeded', 'failed')"
        )
        return int(row["id"])

    async def _refresh_metrics(self) -> None:
        conn = self.app.connector
        depth = {r["status"]: int(r["n"]) for r in await conn.execute_query_all_async(_DEPTH)}
        for status in ("todo", "doing", "succeeded", "failed"):
            self.metrics.queue_jobs.labels(status).set(depth.get(status, 0))
        for r in await conn.execute_query_all_async(_FINISHED, after=self._finished_after):
            self.metrics.queue_job_latency.observe(float(r["seconds"] or 0.0))
            self._finished_after = max(self._finished_after, int(r["id"]))

    async def run_loop(self, name: str, timeout_s: float = 120.0) -> str | None:
        """Diagnose one loop now through the queue (``POST /loops/{id}/diagnose``): its job
        shares the batch's lock, then the loop's stored cause is returned (None on timeout)."""
        batch = self._batch_of.get(name)
        if batch is None:
            return None
        job_id = await self.enqueue(batch, [name])
        if job_id is None:
            return None
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            jobs = list(await self.app.job_manager.list_jobs_async(id=job_id))
            if jobs and jobs[0].status in ("succeeded", "failed"):
                break
            await asyncio.sleep(0.2)
        else:
            return None
        rows = await loop_statuses(self.store, name)
        return rows[0].cause if rows else None


def worker_name() -> str:
    """``host-pid``: which machine and process holds a job (procrastinate_workers)."""
    return f"{socket.gethostname()}-{os.getpid()}"


async def run_worker(
    diagnoser: DiagnosisScheduler,
    url: str,
    concurrency: int,
    *,
    heartbeat_s: float = 10.0,
    stalled_after_s: float = 30.0,
) -> None:
    """Run queued diagnosis jobs until SIGINT/SIGTERM (``plantcheck worker``)."""
    app = queue_app(url, max_size=concurrency + 2)

    async def diagnose_batch(loops: list[str], enqueued_us: int = 0) -> dict[str, int]:
        known = [n for n in loops if n in diagnoser.schedules]
        if len(known) < len(loops):
            log.warning(
                "loops %s are not in this worker's configuration: skipped (give the worker the "
                "service's configuration file)",
                ", ".join(sorted(set(loops) - set(known))),
            )
        await diagnoser.adopt_shared_history(known)
        causes = await asyncio.gather(*(diagnoser.run_loop(n) for n in known))
        failed = sum(c is None for c in causes)
        if known and failed == len(known):
            raise RuntimeError(f"every diagnosis of the batch failed ({failed} loops)")
        return {"diagnosed": len(known) - failed, "failed": failed}

    app.task(name=TASK, queue=QUEUE)(diagnose_batch)
    async with app.open_async():
        await ensure_queue_schema(app)
        log.info(
            "worker %s: %d concurrent jobs, %d diagnosis processes",
            worker_name(),
            concurrency,
            diagnoser.workers,
        )
        await app.run_worker_async(
            queues=[QUEUE],
            concurrency=concurrency,
            name=worker_name(),
            update_heartbeat_interval=heartbeat_s,
            stalled_worker_timeout=stalled_after_s,
            shutdown_graceful_timeout=10.0,
            install_signal_handlers=True,
        )
    log.info("worker %s stopped", worker_name())
