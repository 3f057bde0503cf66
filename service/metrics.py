"""Prometheus metrics of one service instance (prometheus-client, its own registry).

- ``plantcheck_samples_received_total`` / ``plantcheck_samples_stored_total``: samples taken from
  the connectors and committed to the store (Prometheus' ``rate()`` gives samples/s);
  ``plantcheck_samples_per_second``: received samples per second over the last minute.
- ``plantcheck_buffer_depth``: samples waiting in memory and in the durable buffer.
- ``plantcheck_diagnosis_duration_seconds``: read + diagnose + store time per loop window.
- ``plantcheck_loops``: loops per state (``ok``, ``warning``, ``fault``, ``unknown``).
- ``plantcheck_diagnoses_total``: diagnoses by outcome (``done``, ``failed``).
- ``plantcheck_window_cache_bytes``: memory held by the scheduler's rolling windows.
"""

from __future__ import annotations

import time
from collections import deque

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest

from plantcheck.diagnosis.result import STATES


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
            "Samples waiting to be stored (memory queue and durable buffer).",
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
        for s in STATES:
            self.loops.labels(s).set(0)
        self._received: deque[tuple[float, int]] = deque()
        self._received_total = 0

    def received(self, n: int) -> None:
        """Count ``n`` samples taken from a connector."""
        self.samples_received.inc(n)
        self._received_total += n

    def sample_rate(self, now: float | None = None, span_s: float = 60.0) -> float:
        """Received samples per second over the last ``span_s`` seconds (updates the gauge)."""
        now = time.monotonic() if now is None else now
        self._received.append((now, self._received_total))
        while len(self._received) > 1 and now - self._received[0][0] > span_s:
            self._received.popleft()
        t0, n0 = self._received[0]
        rate = (self._received_total - n0) / (now - t0) if now > t0 else 0.0
        self.samples_per_second.set(rate)
        return rate

    def set_loop_states(self, counts: dict[str, int]) -> None:
        for s in STATES:
            self.loops.labels(s).set(counts.get(s, 0))

    def render(self) -> bytes:
        """The Prometheus text exposition."""
        return generate_latest(self.registry)
