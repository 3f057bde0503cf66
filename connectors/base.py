"""What every connector shares: the sample sink, per-device tasks with backoff, and logging a
failure once and its recovery once (as Home Assistant's update coordinator does).

A connector module (one per protocol) subclasses ``DeviceConnector`` and implements
``connect``, ``collect`` and ``close``. ``run()`` keeps one device alive on its own task: it
polls or waits for subscriptions, and on a failure it marks a gap (a Bad
``BAD_NO_COMMUNICATION`` sample with no value for every tag), closes, and reconnects with
exponential backoff and jitter; the device is back (and the back-off reset) at its first data,
not at connect, so one that accepts connections but does not answer backs off further. While
it backs off, the device's TCP endpoint is probed every ``PROBE_S``: a server that was not
listening and listens again is tried at once, not when the back-off clock says (issue 45: a
server back after 5 s was read again 9-13 s later). A failing device never slows the others.

Held tags (a polled source's SP and mode, which keep their value between samples) are passed on
only when their value or status changes, again after every gap marker, and at least every
``HELD_REFRESH_S`` (so a sample dropped on the way, by a full buffer, is not missing for good):
what an OPC UA subscription reports, plus that refresh. A set point read every second for an
hour is 6 stored samples, not 3,600; the windows hold it in between (``storage.window.align``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass

from plantcheck.core.samples import Sample
from plantcheck.core.source_health import SourceHealth
from plantcheck.core.status_codes import BAD_NO_COMMUNICATION

__all__ = ["DeviceConnector", "SampleSink", "SourceHealth", "now_us"]

SampleSink = Callable[[Sequence[Sample]], None]

log = logging.getLogger("plantcheck.connectors")


HELD_REFRESH_S = 600.0
"""Longest time (s, source time) between two passed-on samples of an unchanged held tag."""


PROBE_S = 0.5
"""How often a backing-off device's endpoint is probed for a server that listens again (s)."""


async def listening(host: str, port: int, timeout_s: float = 1.0) -> bool:
    """A TCP connection to ``host:port`` is accepted (closed again at once)."""
    try:
        _, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout_s)
    except (OSError, TimeoutError):
        return False
    writer.close()
    with contextlib.suppress(OSError):
        await writer.wait_closed()
    return True


def now_us() -> int:
    return time.time_ns() // 1000


@dataclass
class DeviceState:
    """Health of one device: last success, current failure, counters."""

    connected: bool = False
    last_success_us: int | None = None
    failing_since_us: int | None = None
    last_error: str = ""
    failures: int = 0
    samples: int = 0
    up_since_us: int | None = None
    """When the device last came back (its first data after a failure or at start)."""
    attempt_us: int | None = None
    """When the current (or last) connection attempt began."""


class DeviceConnector(ABC):
    """One device or server, polled or subscribed on its own task."""

    protocol: str = ""
    """The configuration's name of the protocol (``modbus``, ``opcua``)."""

    def __init__(
        self,
        name: str,
        sink: SampleSink,
        tag_ids: Sequence[int],
        *,
        backoff_initial_s: float = 0.5,
        backoff_max_s: float = 30.0,
        held: Collection[int] = (),
    ) -> None:
        self.name = name
        self.sink = sink
        self.tag_ids = list(tag_ids)
        self.state = DeviceState()
        self.backoff_initial_s = backoff_initial_s
        self.backoff_max_s = backoff_max_s
        self._stop = asyncio.Event()
        self._gap_us = 0
        self._after_gap: set[int] = set()
        self._delay = backoff_initial_s
        """Current reconnection back-off, s."""
        self.held = frozenset(held)
        """Tags passed on only when they change (see the module docstring)."""
        self._held_last: dict[int, tuple[float | None, int, int]] = {}
        """Per held tag: value, status and source time (µs) of the last sample passed on."""

    @abstractmethod
    async def connect(self) -> None:
        """Open the connection (raise on failure)."""

    @abstractmethod
    async def collect(self) -> None:
        """Run while connected, handing samples to ``self.emit``; raise on connection loss."""

    @abstractmethod
    async def close(self) -> None:
        """Close the connection (never raises)."""

    def endpoint(self) -> tuple[str, int] | None:
        """The server's TCP host and port, probed while backing off (None: not probed)."""
        return None

    def emit(self, rows: Sequence[Sample]) -> None:
        if self.held:
            rows = self._held_changes(rows)
        if self._after_gap:
            rows = [self._not_before_gap(r) for r in rows]
        self.state.samples += len(rows)
        self.state.last_success_us = now_us()
        if not self.state.connected:
            # back only once data flows: a device that accepts connections but does not
            # answer keeps failing, and its back-off keeps growing
            self._recovered()
            self._delay = self.backoff_initial_s
        self.sink(rows)

    def gap_time_us(self) -> int:
        """When an outage begins, on the samples' time axis (the receiver's clock here)."""
        return now_us()

    def mark_gap(self) -> None:
        """Store a gap marker for every tag: Bad (no communication), no value."""
        t = self.gap_time_us()
        self.sink([Sample(tid, t, t, None, BAD_NO_COMMUNICATION) for tid in self.tag_ids])
        self._gap_us = t
        self._after_gap = set(self.tag_ids)
        self._held_last.clear()

    def _held_changes(self, rows: Sequence[Sample]) -> list[Sample]:
        """``rows`` without the held tags' samples that repeat the last value and status
        passed on less than ``HELD_REFRESH_S`` before."""
        out = []
        refresh_us = int(HELD_REFRESH_S * 1e6)
        for r in rows:
            if r.tag_id in self.held:
                last = self._held_last.get(r.tag_id)
                if last and last[:2] == (r.value, r.status) and r.ts_us - last[2] < refresh_us:
                    continue
                self._held_last[r.tag_id] = (r.value, r.status, r.ts_us)
            out.append(r)
        return out

    def _not_before_gap(self, r: Sample) -> Sample:
        """The first sample of a tag after a gap marker is never stored before the marker.

        A server that reports only changes (OPC UA) sends, on reconnection, a constant value
        with the source timestamp of its last change; stored as it is, it would sit before the
        marker and the gap would hide a value that in fact held. Stored just after the marker,
        it is held from there on.
        """
        if r.tag_id not in self._after_gap:
            return r
        self._after_gap.discard(r.tag_id)
        return r if r.ts_us > self._gap_us else r._replace(ts_us=self._gap_us + 1)

    def health(self) -> SourceHealth:
        """The device's state as the API shows it."""
        st = self.state
        since: int | None
        if st.failing_since_us is not None:
            state, since = "down", st.failing_since_us
        elif st.connected:
            state, since = "up", st.up_since_us
        else:
            state, since = "unknown", None
        return SourceHealth(
            self.name, self.protocol, state, since, st.last_success_us, st.failures, st.last_error
        )

    def _failed(self, exc: BaseException) -> None:
        self.state.failures += 1
        self.state.last_error = f"{type(exc).__name__}: {exc}"
        if self.state.failing_since_us is None:
            log.error("%s: unavailable: %s", self.name, self.state.last_error)
            self.state.failing_since_us = now_us()
        if self.state.connected:
            self.mark_gap()
        self.state.connected = False

    def _recovered(self) -> None:
        if self.state.failing_since_us is not None:
            down = (now_us() - self.state.failing_since_us) / 1e6
            # what the successful attempt itself took tells a slow reconnection (a loaded
            # machine, a server slow to open sessions) from a late one (the back-off clock)
            took = (now_us() - (self.state.attempt_us or now_us())) / 1e6
            log.warning(
                "%s: back after %.1f s (this connection took %.1f s)", self.name, down, took
            )
        self.state.failing_since_us = None
        self.state.connected = True
        self.state.up_since_us = now_us()

    async def run(self) -> None:
        """Connect, collect, reconnect with backoff, until ``stop()``. The device counts as
        back (logged once, back-off reset) at its first data, not at connect."""
        self._delay = self.backoff_initial_s
        returned = False
        while not self._stop.is_set():
            if returned:
                # a server that has just come back may refuse its first sessions while it
                # starts: try it again soon, not a back-off grown over its whole outage
                self._delay = self.backoff_initial_s
            self.state.attempt_us = now_us()
            try:
                await self.connect()
                await self.collect()
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                self._failed(exc)
            finally:
                if self._stop.is_set() and self.state.connected:
                    self.mark_gap()  # stopping: what comes after is unknown until restart
                    self.state.connected = False
                await self.close()
            if self._stop.is_set():
                break
            wait = self._delay * random.uniform(0.8, 1.2)
            self._delay = min(self._delay * 2, self.backoff_max_s)
            returned = await self._back_off(wait)

    async def _back_off(self, wait_s: float) -> bool:
        """Wait ``wait_s`` before the next try, or less: until stopped, or until the endpoint,
        seen not listening during this wait, listens again (the server is back: True)."""
        end = time.monotonic() + wait_s
        addr = self.endpoint()
        # probed at once: a server back within the first probe interval was otherwise first
        # seen listening, never seen down, and the whole back-off was waited out
        was_down = addr is not None and not await listening(*addr)
        while not self._stop.is_set():
            left = end - time.monotonic()
            if left <= 0:
                return False
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stop.wait(), min(left, PROBE_S))
            if addr is not None and not self._stop.is_set():
                up = await listening(*addr)
                if up and was_down:
                    # when the service reacted, apart from what the server then takes to
                    # serve a session (the fault suite times both)
                    log.info("%s: %s:%d listens again: trying now", self.name, *addr)
                    return True
                was_down = was_down or not up
        return False

    def stop(self) -> None:
        self._stop.set()

    async def sleep(self, seconds: float) -> bool:
        """Sleep unless stopped; False when stopping."""
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._stop.wait(), seconds)
        return not self._stop.is_set()
