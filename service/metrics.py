"""Prometheus metrics of one service instance (prometheus-client, its own registry).

- ``plantcheck_samples_received_total`` / ``plantcheck_samples_stored_total``: samples taken from
  the connectors and committed to the store (Prometheus' ``rate()`` gives samples/s);
  ``plantcheck_samples_per_second``: received samples per second over the last minute.
- ``plantcheck_buffer_depth``: samples waiting because the store did not take them (in the
  durable buffer, and in memory while commits fail); 0 while the store keeps up.
- ``plantcheck_diagnosis_duration_seconds``: read + diagnose + store time per loop window.
- ``plantcheck_loops``: loops per state (``ok``, ``warning``, ``fault``, ``unknown``);
  ``plantcheck_loop_state{loop, state}``: 1 for each loop's current state.
- ``plantcheck_store_up``: 1 while the sample writer commits to the database, 0 while it
  buffers on disk; ``plantcheck_store_failures_total``: failed commits.
- ``plantcheck_buffer_up``: 1 while the durable buffer takes samples, 0 while its disk fails;
  ``plantcheck_samples_held``: samples held in memory (neither side takes them);
  ``plantcheck_samples_dropped_total``: samples lost (buffer or memory full).
- ``plantcheck_source_up{source, protocol}``: 1 while the source delivers data, 0 while it is
  down or not yet connected.
- ``plantcheck_diagnoses_total``: diagnoses by outcome (``done``, ``failed``).
- ``plantcheck_window_cache_bytes``: memory held by the scheduler's rolling windows.
- ``plantcheck_scheduler_leader``: 1 while this process schedules the diagnosis (it holds the
  scheduler lock on PostgreSQL; on SQLite the one process always does), 0 while it stands by.
- Job queue (``engine = "queue"``): ``plantcheck_queue_jobs{status}`` (jobs by status),
  ``plantcheck_queue_job_latency_seconds`` (enqueued to finished),
  ``plantcheck_queue_jobs_skipped_total`` (a batch still waiting at its next period),
  ``plantcheck_queue_jobs_recovered_total`` (jobs of dead workers handed on).
"""

from __future__ import annotations

import time
from collections import Counter as Counter_
from collections import deque
from collections.abc import Sequence

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest

from plantcheck.core.source_health import SourceHealth
from plantcheck.core.vocabulary import STATES


class ServiceMetrics:
    """The metric objects, registered in a registry owned by this instance."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        r = self.registry
        self.samples_received = Counter(
            "plantcheck_samples_received", "Samples received from the connectors.", registry=r
        )
        self.samples_stored = Counter(
            "plantcheck_samples_stored", "Samples committed to the store.", registry=r
        )
        self.samples_per_second = Gauge(
            "plantcheck_samples_per_second",
            "Samples received per second over the last minute.",
            registry=r,
        )
        self.buffer_depth = Gauge(
            "plantcheck_buffer_depth",
            "Samples waiting because the store did not take them (buffer, memory).",
            registry=r,
        )
        self.diagnosis_duration = Histogram(
            "plantcheck_diagnosis_duration_seconds",
            "Time to read, diagnose and store one loop window.",
            buckets=(0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0),
            registry=r,
        )
        self.diagnoses = Counter(
            "plantcheck_diagnoses", "Loop windows diagnosed.", ["outcome"], registry=r
        )
        self.loops = Gauge("plantcheck_loops", "Loops per state.", ["state"], registry=r)
        self.window_cache_bytes = Gauge(
            "plantcheck_window_cache_bytes",
            "Memory held by the rolling windows kept between diagnoses.",
            registry=r,
        )
        self.loop_state = Gauge(
            "plantcheck_loop_state",
            "1 for the loop's current state.",
            ["loop", "state"],
            registry=r,
        )
        self.store_up = Gauge(
            "plantcheck_store_up",
            "1 while samples are committed to the database, 0 while they are buffered.",
            registry=r,
        )
        self.store_failures = Counter(
            "plantcheck_store_failures", "Failed commits of samples to the database.", registry=r
        )
        self._store_failures_seen = 0
        self.buffer_up = Gauge(
            "plantcheck_buffer_up",
            "1 while the durable buffer takes samples, 0 while its disk fails.",
            registry=r,
        )
        self.samples_held = Gauge(
            "plantcheck_samples_held",
            "Samples held in memory because neither the database nor the buffer takes them.",
            registry=r,
        )
        self.samples_dropped = Counter(
            "plantcheck_samples_dropped",
            "Samples lost because the durable buffer or the memory queue was full.",
            registry=r,
        )
        self._dropped_seen = 0
        self.source_up = Gauge(
            "plantcheck_source_up",
            "1 while the source delivers data, else 0.",
            ["source", "protocol"],
            registry=r,
        )
        self.leader = Gauge(
            "plantcheck_scheduler_leader",
            "1 while this process holds the scheduler lock, 0 while it stands by.",
            registry=r,
        )
        self.queue_jobs = Gauge(
            "plantcheck_queue_jobs",
            "Diagnosis jobs in the queue by status.",
            ["status"],
            registry=r,
        )
        self.queue_job_latency = Histogram(
            "plantcheck_queue_job_latency_seconds",
            "Time from queueing a diagnosis job to its end.",
            buckets=(0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0),
            registry=r,
        )
        self.queue_jobs_skipped = Counter(
            "plantcheck_queue_jobs_skipped",
            "Batches not queued because their last job still waited.",
            registry=r,
        )
        self.queue_jobs_recovered = Counter(
            "plantcheck_queue_jobs_recovered",
            "Jobs of dead workers handed to the queue again.",
            registry=r,
        )
        self.alerts = Counter(
            "plantcheck_alerts",
            "Alert delivery attempts by outcome (delivered, retried, failed).",
            ["status"],
            registry=r,
        )
        self.alerts_pending = Gauge(
            "plantcheck_alerts_pending", "Alerts waiting in the outbox.", registry=r
        )
        for s in STATES:
            self.loops.labels(s).set(0)
        self._received: deque[tuple[float, int]] = deque([(time.monotonic(), 0)])
        """(time, samples received so far) at each scrape, back to the last one older than
        the span, and the start: the rate spans at least the span whatever the scrape pace."""
        self._received_total = 0

    def received(self, n: int) -> None:
        """Count ``n`` samples taken from a connector."""
        self.samples_received.inc(n)
        self._received_total += n

    def sample_rate(self, now: float | None = None, span_s: float = 60.0) -> float:
        """Received samples per second over the last ``span_s`` seconds (updates the gauge)."""
        now = time.monotonic() if now is None else now
        self._received.append((now, self._received_total))
        # keep the newest point at least ``span_s`` old: scraped every 15 s or every 5 min,
        # the rate is over the last minute or more, never over no time at all (issue 47)
        while len(self._received) > 2 and now - self._received[1][0] >= span_s:
            self._received.popleft()
        t0, n0 = self._received[0]
        rate = (self._received_total - n0) / (now - t0) if now > t0 else 0.0
        self.samples_per_second.set(rate)
        return rate

    def set_loop_states(self, states: dict[str, str]) -> None:
        """Loops per state and each loop's state, from ``{loop id: state}``."""
        counts = Counter_(states.values())
        for s in STATES:
            self.loops.labels(s).set(counts.get(s, 0))
        self.loop_state.clear()
        for loop, state in states.items():
            self.loop_state.labels(loop, state).set(1)

    def set_store(self, up: bool, failures: int) -> None:
        """The sample writer's state: up or buffering, and its failed commits so far."""
        self.store_up.set(1 if up else 0)
        if failures > self._store_failures_seen:
            self.store_failures.inc(failures - self._store_failures_seen)
            self._store_failures_seen = failures

    def set_buffer(self, up: bool, held: int, dropped: int) -> None:
        """The durable buffer's state, the samples held in memory, the samples lost so far."""
        self.buffer_up.set(1 if up else 0)
        self.samples_held.set(held)
        if dropped > self._dropped_seen:
            self.samples_dropped.inc(dropped - self._dropped_seen)
            self._dropped_seen = dropped

    def set_sources(self, sources: Sequence[SourceHealth]) -> None:
        for h in sources:
            self.source_up.labels(h.name, h.protocol).set(1 if h.state == "up" else 0)

    def render(self) -> bytes:
        """The Prometheus text exposition."""
        return generate_latest(self.registry)
