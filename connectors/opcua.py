"""OPC UA client (asyncua 2.1): data-change subscriptions, polling as the fallback.

Monitored items sample at ``sampling_interval_s`` with no deadband (raw samples: the diagnosis
needs them) and a queue sized for the publishing interval, so no sample between two publish
responses is lost. Source timestamps are kept (server timestamp, then receive time, when a
server sends none); a Bad status is stored with no value.

The connector owns its session (issue 27). asyncua's ``auto_reconnect`` could fail to restore a
subscription after a server stall of 10-20 s ("Failed to restore subscription"), keep an empty
one and stay silent for good while the server state still read fine. Here a lost connection
(asyncua's own health probe) ends the session: ``run()`` stores a gap marker and builds a new
client, session, subscription and monitored items with back-off. A data watchdog covers what
the probe cannot see: when no data change arrived for ``watchdog_s``, the tags are read once;
a read that fails, or source times newer than the last ones received, mean the subscription is
dead, and the session is rebuilt the same way (constant tags, which report nothing, pass).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Sequence
from datetime import datetime
from typing import Any
from urllib.parse import urlsplit

from asyncua import Client, ua

from plantcheck.connectors.base import DeviceConnector, SampleSink, now_us
from plantcheck.connectors.opcua_security import OpcUaSecurity, explain_refusal, secure
from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import BAD_DATA_ENCODING_INVALID, is_bad

log = logging.getLogger("plantcheck.connectors")


SESSION_TIMEOUT_MS = 600_000
"""Session timeout asked of the server (ms)."""


def _us(t: datetime | None) -> int | None:
    return None if t is None else round(t.timestamp() * 1e6)


def to_sample(tag_id: int, dv: Any, recv_us: int) -> Sample:
    """A stored sample from an OPC UA DataValue."""
    status = int(dv.StatusCode.value) if dv.StatusCode is not None else 0
    ts = _us(dv.SourceTimestamp) or _us(dv.ServerTimestamp) or recv_us
    value: float | None = None
    if not is_bad(status):
        try:
            value = float(dv.Value.Value)
        except (TypeError, ValueError, AttributeError):
            value = None
        if value is None or not math.isfinite(value):
            status, value = BAD_DATA_ENCODING_INVALID, None
    return Sample(tag_id, ts, recv_us, value, status)


class _Handler:
    """One session's subscription handler. A session given up (stalled, then replaced) can
    still deliver notifications it had queued once its server answers again: values from
    before the outage, which, stored after it was marked, would split the marked outage
    into a marked part and a silent one (the fault suite found a 5-s silent hole so). Only
    the current session's notifications are passed on."""

    def __init__(self, owner: OpcUaConnector) -> None:
        self.owner = owner
        self.session = owner.session

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        if self.session != self.owner.session:
            return
        tag_id = self.owner.by_node.get(node.nodeid.to_string())
        if tag_id is not None:
            self.owner.emit([to_sample(tag_id, data.monitored_item.Value, now_us())])

    def status_change_notification(self, status: Any) -> None:
        log.warning("%s: subscription status %s", self.owner.name, status)


class OpcUaConnector(DeviceConnector):
    """Subscribes to (or polls) the tags of one OPC UA server."""

    protocol = "opcua"

    def __init__(
        self,
        name: str,
        sink: SampleSink,
        tags: Sequence[tuple[int, str]],
        *,
        url: str,
        sampling_interval_s: float = 1.0,
        mode: str = "subscribe",
        timeout_s: float = 4.0,
        watchdog_s: float | None = None,
        security: OpcUaSecurity | None = None,
        **kw: float,
    ) -> None:
        super().__init__(name, sink, [t for t, _ in tags], held=(), **kw)  # changes only already
        self.url = url
        self.security = security
        self.configured = [(tid, ua.NodeId.from_string(n)) for tid, n in tags]
        """Node ids as configured: ``nsu=`` ones name their namespace by URI."""
        self.nodes = self.configured
        self.by_node = {n.to_string(): tid for tid, n in self.nodes}
        self.sampling_interval_s = sampling_interval_s
        self.mode = mode
        self.timeout_s = timeout_s
        self.client: Client | None = None
        self.session = 0
        """Counts the sessions made: a handler passes on only its own session's data."""
        self.polling = mode == "poll"
        publish_s = max(sampling_interval_s, 0.5)
        self.watchdog_s = watchdog_s if watchdog_s is not None else max(5.0, 5 * publish_s)
        """No data change for this long (s) -> read the tags to check the subscription."""
        self._lost_exc: Exception | None = None
        self._last_data_us = 0
        self._last_ts: dict[int, int] = {}
        """Per tag, the newest source time (µs) received."""

    def endpoint(self) -> tuple[str, int] | None:
        """The endpoint URL's host and port (4840, the OPC UA default, when it names none)."""
        try:
            u = urlsplit(self.url)
            return (u.hostname, u.port or 4840) if u.hostname else None
        except ValueError:
            return None

    async def _lost(self, exc: Exception) -> None:
        self._lost_exc = exc

    async def connect(self) -> None:
        # the session is ours: a loss ends it and run() builds a new one (module docstring)
        self.session += 1
        # asyncua's health probe waits min(session timeout / 2, watchdog interval) for the
        # server state: 1 s by default, which a loaded machine's server exceeded (the demo lost
        # its session beside a busy process, and 130 simulated seconds with it); it now waits
        # as long as any request does (the source's timeout_s), and probes as often
        client = Client(
            self.url,
            timeout=self.timeout_s,
            watchdog_intervall=max(1.0, self.timeout_s),
            auto_reconnect=False,
        )
        # 10 minutes, what servers commonly grant (asyncua asks an hour, and warns at every
        # connection when the server revises it down)
        client.session_timeout = SESSION_TIMEOUT_MS
        client.connection_lost_callback = self._lost
        self._lost_exc = None
        try:
            if self.security is not None:
                await secure(client, self.security, self.name)
            await client.connect()
        except Exception as exc:
            hint = explain_refusal(exc, self.security) if self.security else None
            if hint is None:
                raise
            raise ConnectionRefusedError(hint) from exc
        self.client = client
        try:
            await self._resolve_namespaces()
        except Exception:
            await self.close()
            raise
        self._last_data_us = now_us()

    async def _resolve_namespaces(self) -> None:
        """Give ``nsu=`` node ids the index the server has for their namespace URI now (an
        index may change when the server restarts; the URI does not)."""
        if not any(getattr(n, "NamespaceUri", None) for _, n in self.configured):
            return
        assert self.client is not None
        table = list(await self.client.get_namespace_array())
        nodes = []
        for tid, n in self.configured:
            uri = getattr(n, "NamespaceUri", None)
            if uri:
                if uri not in table:
                    raise LookupError(
                        f"namespace {uri!r} is not on this server (it has: {', '.join(table)})"
                    )
                n = ua.NodeId(n.Identifier, table.index(uri), n.NodeIdType)
            nodes.append((tid, n))
        self.nodes = nodes
        self.by_node = {n.to_string(): tid for tid, n in nodes}

    def gap_time_us(self) -> int:
        """Just after the newest source time received: the marker belongs on the server's
        time axis. On the receiver's clock it fell among the samples of the outage whenever
        the server's clock ran behind (a simulator late under load, a plant clock off), and
        those, stored before it, made a silent hole of a marked outage (the fault suite)."""
        return max(self._last_ts.values()) + 1 if self._last_ts else now_us()

    def emit(self, rows: Sequence[Sample]) -> None:
        self._last_data_us = now_us()
        for r in rows:
            if r.ts_us > self._last_ts.get(r.tag_id, 0):
                self._last_ts[r.tag_id] = r.ts_us
        super().emit(rows)

    async def _read_all(self) -> list[Any]:
        """One read of every tag's value with both timestamps (DataValues, in tag order)."""
        assert self.client is not None
        params = ua.ReadParameters()
        params.NodesToRead = [
            ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.Value) for _, n in self.nodes
        ]
        params.TimestampsToReturn = ua.TimestampsToReturn.Both
        return list(await asyncio.wait_for(self.client.uaclient.read(params), self.timeout_s))

    async def _check_subscription(self) -> None:
        """Raise when the subscription has gone silent while the tags still change."""
        dvs = await self._read_all()
        recv = now_us()
        late = int(self.watchdog_s * 1e6)
        for (tid, _), dv in zip(self.nodes, dvs, strict=True):
            sample = to_sample(tid, dv, recv)
            if sample.ts_us > self._last_ts.get(tid, 0) + late:
                raise ConnectionError(
                    f"subscription silent for {self.watchdog_s:g} s while the values change"
                )
        self._last_data_us = recv  # constant values: nothing to report, the session is alive

    async def _subscribe(self) -> None:
        assert self.client is not None
        sampling_ms = self.sampling_interval_s * 1000.0
        publish_ms = max(sampling_ms, 500.0)
        queue = max(10, math.ceil(2 * publish_ms / max(sampling_ms, 1.0)))
        sub = await self.client.create_subscription(publish_ms, _Handler(self))
        items = [
            ua.MonitoredItemCreateRequest(
                ItemToMonitor=ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.Value),
                MonitoringMode=ua.MonitoringMode.Reporting,
                RequestedParameters=ua.MonitoringParameters(
                    ClientHandle=i,
                    SamplingInterval=sampling_ms,
                    QueueSize=queue,
                    DiscardOldest=True,
                ),
            )
            for i, (_, n) in enumerate(self.nodes)
        ]
        results = await sub.create_monitored_items(items)
        bad = [r for r in results if isinstance(r, ua.StatusCode)]
        if bad:
            log.error("%s: %d node(s) could not be monitored: %s", self.name, len(bad), bad[0])

    async def _poll_once(self) -> None:
        dvs = await self._read_all()
        recv = now_us()
        self.emit([to_sample(tid, dv, recv) for (tid, _), dv in zip(self.nodes, dvs, strict=True)])

    async def collect(self) -> None:
        if not self.polling:
            try:
                await self._subscribe()
            except Exception as exc:  # server without subscriptions: poll instead
                log.warning("%s: subscriptions unavailable (%s); polling", self.name, exc)
                self.polling = True
        while True:
            if self.polling:
                await self._poll_once()
            if not await self.sleep(self.sampling_interval_s if self.polling else 1.0):
                return
            if self._lost_exc is not None:
                raise self._lost_exc
            silent_s = (now_us() - self._last_data_us) / 1e6
            if not self.polling and silent_s > self.watchdog_s:
                await self._check_subscription()

    async def close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self.client.disconnect(), 5)
            self.client = None
