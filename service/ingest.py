"""Build the connectors of a configuration: one per source, all its loops' tags."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from plantcheck.connectors.base import DeviceConnector, SampleSink, SourceHealth, now_us
from plantcheck.connectors.modbus import ModbusConnector, ModbusTag
from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import BAD_NO_COMMUNICATION
from plantcheck.service.config import Config, SourceConfig
from plantcheck.storage.database import sqlite_file
from plantcheck.storage.source_health import report_health
from plantcheck.storage.store import LoopRow, Store
from plantcheck.storage.window import HELD
from plantcheck.storage.writer import SampleWriter

if TYPE_CHECKING:
    from plantcheck.connectors.opcua_security import OpcUaSecurity

log = logging.getLogger("plantcheck.ingest")

HEALTH_REPORT_S = 5.0
"""How often the sources' health is stored for the central service (s)."""


def security_of(src: SourceConfig) -> OpcUaSecurity | None:
    """The OPC UA security of a source (None: ``security_policy = "None"``)."""
    if src.security_policy == "None":
        return None
    from plantcheck.connectors.opcua_security import OpcUaSecurity

    return OpcUaSecurity(
        certificate=Path(src.certificate),
        private_key=Path(src.private_key),
        mode=src.security_mode,
        server_certificate=Path(src.server_certificate) if src.server_certificate else None,
        username=src.username,
        password=src.password.get_secret_value(),
    )


def build_connectors(
    cfg: Config, loops: dict[str, LoopRow], sink: SampleSink
) -> list[DeviceConnector]:
    """The connectors for every configured source that has at least one loop."""
    out: list[DeviceConnector] = []
    for src in cfg.source:
        mine = [lp for lp in cfg.loop if lp.source == src.name]
        if not mine:
            continue
        if src.protocol == "modbus":
            mtags = []
            held = set()
            for lp in mine:
                for sig, address in lp.tags().items():
                    sc = lp.scale.get(sig)  # type: ignore[call-overload]
                    gain, offset = (sc.gain, sc.offset) if sc else (1.0, 0.0)
                    tag_id = loops[lp.id].tags[sig]
                    mtags.append(ModbusTag.parse(tag_id, address, gain, offset))
                    if sig in HELD:  # SP, mode: stored when they change, as OPC UA reports
                        held.add(tag_id)
            out.append(
                ModbusConnector(
                    src.name,
                    sink,
                    mtags,
                    host=src.host,
                    port=src.port,
                    device_id=src.device_id,
                    word_order=src.word_order,
                    byte_order=src.byte_order,
                    poll_interval_s=src.poll_interval_s,
                    timeout_s=src.timeout_s,
                    held=held,
                    clock=src.clock,
                )
            )
        else:
            # asyncua (0.6-0.7 s to import) only for a service that reads OPC UA
            from plantcheck.connectors.opcua import OpcUaConnector

            utags = [
                (loops[lp.id].tags[sig], address)
                for lp in mine
                for sig, address in lp.tags().items()
            ]
            out.append(
                OpcUaConnector(
                    src.name,
                    sink,
                    utags,
                    url=src.url,
                    sampling_interval_s=src.poll_interval_s,
                    mode=src.mode,
                    timeout_s=src.timeout_s,
                    security=security_of(src),
                )
            )
    return out


async def restart_gaps(store: Store, writer: SampleWriter, tag_ids: Sequence[int]) -> list[Sample]:
    """Gap markers that close what a crash left open (issue 27).

    After ``kill -9`` the newest sample of a tag (stored, or still in the durable buffer) is a
    value, not a gap marker: the windows would hold it across the dead time. A marker just
    after it (1 µs later) says nothing is known from there until the first new sample.
    """
    wanted = set(tag_ids)
    newest = await store.newest_samples(tag_ids)
    for tid, (ts, st) in writer.buffer.newest().items():
        if tid in wanted and (tid not in newest or ts > newest[tid][0]):
            newest[tid] = (ts, st)
    now = now_us()
    return [
        Sample(tid, ts + 1, now, None, BAD_NO_COMMUNICATION)
        for tid, (ts, st) in newest.items()
        if st != BAD_NO_COMMUNICATION
    ]


def down_past_grace(cfg: Config, health: Sequence[SourceHealth], now_us: int) -> list[str]:
    """The sources of ``health`` down longer than their ``down_grace_s``."""
    grace = {s.name: s.down_grace_s for s in cfg.source}
    return [
        h.name
        for h in health
        if h.state == "down" and h.down_for_s(now_us) > grace.get(h.name, 0.0)
    ]


def shares_a_disk(url: str, buffer_path: Path) -> bool:
    """A SQLite database and the durable buffer on one filesystem: one full or read-only disk
    then stops both, and samples can only wait in memory (issue 45)."""
    db = sqlite_file(url)
    if db is None or str(buffer_path) == ":memory:":
        return False
    try:
        a = os.stat(db.resolve().parent).st_dev
        b = os.stat(buffer_path.resolve().parent).st_dev
    except OSError:
        return False
    return a == b


class Ingestion:
    """Store, sample writer and connectors of one configuration, running together."""

    def __init__(
        self,
        cfg: Config,
        store: Store,
        writer: SampleWriter,
        connectors: list[DeviceConnector],
        collector: str = "",
    ) -> None:
        self.cfg = cfg
        self.collector = collector
        self.store = store
        self.writer = writer
        self.connectors = connectors
        self.tasks: list[asyncio.Task[None]] = []
        """One per connector."""
        self._health_task: asyncio.Task[None] | None = None
        self._stop = asyncio.Event()

    @classmethod
    async def start(
        cls,
        cfg: Config,
        config_hint: str = "",
        on_samples: Callable[[int], None] | None = None,
        connect: bool = True,
        collector: str = "",
    ) -> Ingestion:
        """Open the store (refusing an unmigrated one), map the loops, start every device of
        ``collector`` (the service's own: "") — none without ``connect``, which marks no restart
        gaps either; ``on_samples(n)`` is
        told of every batch received.

        A collector stores only its own sources and loops (``Config.read_by``): collectors with
        configuration files of different ages never overwrite each other's loops, and each
        marks restart gaps only on the tags it reads."""
        own = cfg.read_by(collector)
        store = await Store.open(cfg.storage.url, config_hint=config_hint)
        log.info("store: %s", await store.storage_mode())
        loops = await store.sync_config(own if collector else cfg)
        tag_ids = [t for lp in own.loop for t in loops[lp.id].tags.values()]
        writer = SampleWriter(
            store,
            Path(cfg.storage.buffer_path),
            buffer_max_samples=cfg.storage.buffer_max_samples,
            memory_max_samples=cfg.storage.memory_max_samples,
            commit_interval_s=cfg.storage.commit_interval_s,
            retention_s=cfg.storage.retention_days * 86400.0,
            rollup_tags=tag_ids,
            rollup_retention_s=cfg.storage.rollup_retention_days * 86400.0,
        )
        if shares_a_disk(cfg.storage.url, Path(cfg.storage.buffer_path)):
            log.info(
                "the database and the durable buffer %s are on one disk: if it fills or turns "
                "read-only, samples wait in memory (at most %d); put [storage] buffer_path on "
                "another disk or volume (README, 'Where the buffer lives')",
                cfg.storage.buffer_path,
                cfg.storage.memory_max_samples,
            )
        if connect:
            # without connectors nothing restarts reading: the store is served as it is (a
            # marker written then landed, late under load, among the pages a test read)
            writer.put(await restart_gaps(store, writer, tag_ids))
        writer.start()
        sink: SampleSink = writer.put
        if on_samples is not None:
            count = on_samples

            def sink(rows: Sequence[Sample]) -> None:
                count(len(rows))
                writer.put(rows)

        connectors = build_connectors(own, loops, sink) if connect else []
        ing = cls(own, store, writer, connectors, collector)
        ing.tasks = [asyncio.create_task(c.run()) for c in ing.connectors]
        if connectors:
            ing._health_task = asyncio.create_task(ing._report_health(), name="health-report")
        return ing

    async def _report_health(self) -> None:
        """Store the sources' health every ``HEALTH_REPORT_S`` for the central service (a
        failed report is skipped: the next one replaces it)."""
        while not self._stop.is_set():
            with contextlib.suppress(Exception):
                await report_health(self.store, self.collector, self.source_health(), now_us())
            await self.wait(HEALTH_REPORT_S)

    def source_health(self) -> list[SourceHealth]:
        """Every configured source with loops, in configuration order."""
        return [c.health() for c in self.connectors]

    def sources_down_past_grace(self, now_us: int) -> list[str]:
        """Sources down longer than their ``down_grace_s``."""
        return down_past_grace(self.cfg, self.source_health(), now_us)

    async def wait(self, seconds: float | None = None) -> None:
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._stop.wait(), seconds)

    async def stop(self) -> None:
        self._stop.set()
        for c in self.connectors:
            c.stop()
        await asyncio.gather(*self.tasks, return_exceptions=True)
        if self._health_task is not None:
            await asyncio.gather(self._health_task, return_exceptions=True)
        await self.writer.stop()
        await self.store.close()
