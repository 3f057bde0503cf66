"""A server back after an outage is read again soon, even when it refuses its first sessions
while it starts (issue 47: an OPC UA server that listened again was read 6.5 s later on a
loaded machine, because a failed first try sent the connector back to a back-off grown over
the whole outage). A real TCP server on 127.0.0.1; the protocol is one byte of greeting."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sequence

from plantcheck.connectors.base import DeviceConnector
from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import GOOD


class Greeted(DeviceConnector):
    """Connected once the server greets; one sample per connection, then waits for EOF."""

    def __init__(self, port: int, sink: list[tuple[float, Sample]]) -> None:
        super().__init__("dev", lambda rows: self._store(rows), [1], backoff_initial_s=0.1)
        self.port = port
        self.got = sink
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None

    def _store(self, rows: Sequence[Sample]) -> None:
        self.got.extend((time.monotonic(), r) for r in rows if r.value is not None)

    def endpoint(self) -> tuple[str, int] | None:
        return ("127.0.0.1", self.port)

    async def connect(self) -> None:
        self.reader, self.writer = await asyncio.open_connection("127.0.0.1", self.port)
        if await asyncio.wait_for(self.reader.read(1), 2.0) != b"x":
            raise ConnectionError("closed before the greeting: the server is starting")

    async def collect(self) -> None:
        assert self.reader is not None
        self.emit([Sample(1, 1, 1, 1.0, GOOD)])
        if await self.reader.read(1) == b"":
            raise ConnectionError("connection closed")

    async def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.writer = None


class Server:
    """Listens, greets (``ready``) or closes at once (starting), and can go down."""

    def __init__(self) -> None:
        self.ready = True
        self.server: asyncio.Server | None = None
        self.port = 0
        self.clients: list[asyncio.StreamWriter] = []

    async def _client(self, _: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        if not self.ready:
            w.close()
            return
        self.clients.append(w)
        w.write(b"x")
        await w.drain()

    async def up(self) -> None:
        self.server = await asyncio.start_server(self._client, "127.0.0.1", self.port)
        self.port = self.server.sockets[0].getsockname()[1]

    async def down(self) -> None:
        assert self.server is not None
        self.server.close()
        for w in self.clients:
            w.close()
        self.clients.clear()
        await self.server.wait_closed()


def test_a_server_that_refuses_its_first_sessions_after_an_outage_is_read_soon() -> None:
    async def body() -> float:
        server = Server()
        await server.up()
        got: list[tuple[float, Sample]] = []
        dev = Greeted(server.port, got)
        task = asyncio.create_task(dev.run())
        while not got:
            await asyncio.sleep(0.05)
        await server.down()
        await asyncio.sleep(4.0)  # the back-off grows to 1.6-3.2 s and more
        server.ready = False
        await server.up()  # listens, but closes sessions while it "starts"
        await asyncio.sleep(0.5)
        server.ready = True
        ready_at = time.monotonic()
        while len(got) < 2:
            await asyncio.sleep(0.05)
        lag = got[-1][0] - ready_at
        dev.stop()
        await server.down()
        await asyncio.wait_for(task, 10.0)
        return lag

    lag = asyncio.run(body())
    # with the grown back-off the next try came 3-6 s after the failed one
    assert lag < 1.5, lag
