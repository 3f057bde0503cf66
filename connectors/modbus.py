"""Modbus TCP poller (pymodbus 3.16): one task per device, contiguous block reads.

Tags (``hr:12:float32``) are grouped per table into blocks of at most 125 registers. Every
``poll_interval_s`` each block is read; the source timestamp is the midpoint between request and
response. Decoding follows the source's word and byte order and the loop's scaling
(``value = raw·gain + offset``). Quality:

- a Modbus exception response → Bad (``BAD_DEVICE_FAILURE``) for the block's tags, no value;
- NaN/inf or an undecodable block → Bad (``BAD_DATA_ENCODING_INVALID``), no value;
- a time-out or a dropped connection → a gap marker, then reconnect with backoff.

SP and mode (``held``) are passed on only when they change, after every gap marker and every
10 minutes, as an OPC UA subscription reports them (``connectors.base``); PV, OP and MV every
poll.
"""

from __future__ import annotations

import math
import time
from collections.abc import AsyncIterator, Collection, Sequence
from dataclasses import dataclass

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from plantcheck.connectors.base import DeviceConnector, SampleSink, now_us
from plantcheck.connectors.modbus_codec import WIDTH, DataType, Order, decode
from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import (
    BAD_DATA_ENCODING_INVALID,
    BAD_DEVICE_FAILURE,
    GOOD,
)

MAX_BLOCK = 125
CLOCK_TAG = -1
"""Tag id of the source's clock register: read with the values, never stored."""


@dataclass(frozen=True)
class ModbusTag:
    """One value in a device: table ``hr``/``ir``, 0-based address, data type, scaling."""

    tag_id: int
    table: str
    address: int
    dtype: DataType
    gain: float = 1.0
    offset: float = 0.0

    @classmethod
    def parse(cls, tag_id: int, spec: str, gain: float = 1.0, offset: float = 0.0) -> ModbusTag:
        table, address, dtype = spec.split(":")
        return cls(tag_id, table, int(address), dtype, gain, offset)  # type: ignore[arg-type]

    @property
    def width(self) -> int:
        return WIDTH[self.dtype]


@dataclass(frozen=True)
class Block:
    table: str
    start: int
    count: int
    tags: tuple[ModbusTag, ...]


def plan_blocks(tags: Sequence[ModbusTag], max_block: int = MAX_BLOCK) -> list[Block]:
    """Group tags into contiguous read blocks of at most ``max_block`` registers per table."""
    blocks: list[Block] = []
    for table in sorted({t.table for t in tags}):
        cur: list[ModbusTag] = []
        for t in sorted((t for t in tags if t.table == table), key=lambda t: t.address):
            if cur and t.address + t.width - cur[0].address > max_block:
                end = max(x.address + x.width for x in cur)
                blocks.append(Block(table, cur[0].address, end - cur[0].address, tuple(cur)))
                cur = []
            cur.append(t)
        if cur:
            end = max(x.address + x.width for x in cur)
            blocks.append(Block(table, cur[0].address, end - cur[0].address, tuple(cur)))
    return blocks


def decode_block(
    block: Block, registers: Sequence[int], ts_us: int, recv_us: int, wo: Order, bo: Order
) -> list[Sample]:
    """Samples of a block's tags from its registers (Bad, no value, when not decodable)."""
    out = []
    for t in block.tags:
        off = t.address - block.start
        chunk = registers[off : off + t.width]
        status, value = GOOD, None
        try:
            if len(chunk) != t.width:
                raise ValueError("short response")
            raw = float(decode(chunk, t.dtype, wo, bo)[0])
            value = raw * t.gain + t.offset
            if not math.isfinite(value):
                status, value = BAD_DATA_ENCODING_INVALID, None
        except ValueError:
            status, value = BAD_DATA_ENCODING_INVALID, None
        out.append(Sample(t.tag_id, ts_us, recv_us, value, status))
    return out


class ModbusConnector(DeviceConnector):
    """Polls one Modbus TCP device."""

    protocol = "modbus"

    def __init__(
        self,
        name: str,
        sink: SampleSink,
        tags: Sequence[ModbusTag],
        *,
        host: str,
        port: int,
        device_id: int = 1,
        word_order: Order = "big",
        byte_order: Order = "big",
        poll_interval_s: float = 1.0,
        timeout_s: float = 2.0,
        held: Collection[int] = (),
        clock: str = "",
        **kw: float,
    ) -> None:
        super().__init__(name, sink, [t.tag_id for t in tags], held=held, **kw)
        self.clock = ModbusTag.parse(CLOCK_TAG, clock) if clock else None
        """The device's clock register (POSIX seconds): it stamps the values read with it.
        Modbus carries no time, so without it a value is stamped when polled, which is plant
        time only for a plant that runs in real time (not an accelerated simulator)."""
        blocks = plan_blocks([*tags, self.clock] if self.clock else tags)
        # the clock's block first: its time stamps the blocks read after it in the same poll
        self.blocks = sorted(blocks, key=lambda b: not any(t.tag_id == CLOCK_TAG for t in b.tags))
        self._clock_us: int | None = None
        """The device clock's last reading (µs since 1970)."""
        self.host, self.port, self.device_id = host, port, device_id
        self.word_order, self.byte_order = word_order, byte_order
        self.poll_interval_s, self.timeout_s = poll_interval_s, timeout_s
        self.client: AsyncModbusTcpClient | None = None

    def endpoint(self) -> tuple[str, int]:
        return self.host, self.port

    def gap_time_us(self) -> int:
        """With a clock register, just after its last reading: the gap marker belongs on the
        device's time axis, which an accelerated simulator runs ahead of the wall clock."""
        return now_us() if self._clock_us is None else self._clock_us + 1

    async def connect(self) -> None:
        self.client = AsyncModbusTcpClient(
            self.host, port=self.port, timeout=self.timeout_s, retries=0, reconnect_delay=0
        )
        if not await self.client.connect():
            raise ConnectionError(f"cannot connect to {self.host}:{self.port}")

    async def read_blocks(self) -> AsyncIterator[list[Sample]]:
        """Read every block once, yielding each block's samples as it arrives (raises on
        time-out or lost connection)."""
        assert self.client is not None
        clock_us: int | None = None
        for b in self.blocks:
            read = (
                self.client.read_holding_registers
                if b.table == "hr"
                else self.client.read_input_registers
            )
            t0 = time.time_ns()
            try:
                r = await read(b.start, count=b.count, device_id=self.device_id)
            except ModbusException as exc:
                raise ConnectionError(f"{self.host}:{self.port}: {exc}") from exc
            t1 = time.time_ns()
            ts = (t0 + t1) // 2000
            if r.isError():
                rows = [Sample(t.tag_id, ts, t1 // 1000, None, BAD_DEVICE_FAILURE) for t in b.tags]
            else:
                rows = decode_block(
                    b, r.registers, ts, t1 // 1000, self.word_order, self.byte_order
                )
            if self.clock is not None:
                clock = [x for x in rows if x.tag_id == CLOCK_TAG]
                if clock and clock[0].value is not None and clock[0].value > 0:
                    clock_us = self._clock_us = round(clock[0].value * 1e6)
                rows = [
                    x._replace(ts_us=clock_us) if clock_us is not None else x
                    for x in rows
                    if x.tag_id != CLOCK_TAG
                ]
            yield rows

    async def collect(self) -> None:
        period = self.poll_interval_s
        next_t = time.monotonic()
        while True:
            # each block goes to the writer as it arrives: a device of thousands of tags takes
            # a good part of a second to poll, and its first blocks would wait for the last
            async for block in self.read_blocks():
                self.emit(block)
            next_t += period
            now = time.monotonic()
            if next_t < now:  # late: skip missed polls instead of bursting
                next_t = now + period - (now - next_t) % period
            if not await self.sleep(next_t - now):
                return

    async def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
