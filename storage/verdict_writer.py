"""Group commit of diagnosis verdicts: one transaction for the verdicts of many loops.

Each stored verdict is a few statements (history row, loop row, action, S/J estimate); written
one transaction per loop they cost as much main-process time as the diagnosis itself. The
scheduler's jobs hand their verdicts to ``VerdictWriter.write`` and wait: the writer collects
what arrives within ``linger_s`` (default 0.25 s) and stores it with ``record_verdicts``, a few
statements for the whole batch. A verdict is stored (or its job sees the error) before
``write`` returns, as with a direct write.
"""

from __future__ import annotations

import asyncio

from plantcheck.storage.results import PendingVerdict, record_verdicts
from plantcheck.storage.store import Store


class VerdictWriter:
    """Batches ``PendingVerdict``s into ``record_verdicts`` calls (one task, started on the
    first write; ``close()`` stores what is queued and stops it)."""

    def __init__(self, store: Store, linger_s: float = 0.25, batch_max: int = 2000) -> None:
        self.store = store
        self.linger_s = linger_s
        self.batch_max = batch_max
        self.batches = 0
        """Transactions written so far."""
        self._queue: list[tuple[PendingVerdict, asyncio.Future[bool]]] = []
        self._wake = asyncio.Event()
        self._closing = False
        self._task: asyncio.Task[None] | None = None

    async def write(self, pending: PendingVerdict) -> bool:
        """Store ``pending`` with the next batch; returns whether the loop's verdict changed
        (raises what the store raised)."""
        if self._closing:
            raise RuntimeError("verdict writer closed")
        fut: asyncio.Future[bool] = asyncio.get_running_loop().create_future()
        self._queue.append((pending, fut))
        self._wake.set()
        if self._task is None:
            self._task = asyncio.create_task(self._run(), name="verdict-writer")
        return await fut

    async def close(self) -> None:
        """Store the queued verdicts and stop."""
        self._closing = True
        self._wake.set()
        if self._task is not None:
            await self._task
            self._task = None

    def _take(self) -> list[tuple[PendingVerdict, asyncio.Future[bool]]]:
        """The next batch: queued order, at most one verdict per loop (a loop's second
        verdict waits for the next batch, so its changes apply in order)."""
        batch: list[tuple[PendingVerdict, asyncio.Future[bool]]] = []
        rest: list[tuple[PendingVerdict, asyncio.Future[bool]]] = []
        seen: set[int] = set()
        for item in self._queue:
            loop_id = item[0].verdict.loop.id
            if loop_id in seen or len(batch) >= self.batch_max:
                rest.append(item)
            else:
                seen.add(loop_id)
                batch.append(item)
        self._queue = rest
        return batch

    async def _run(self) -> None:
        while True:
            await self._wake.wait()
            if not self._closing:
                await asyncio.sleep(self.linger_s)
            batch = self._take()
            if not self._queue:
                self._wake.clear()
            if batch:
                try:
                    changed = await record_verdicts(self.store, [p for p, _ in batch])
                except Exception as exc:
                    for _, fut in batch:
                        if not fut.done():
                            fut.set_exception(exc)
                else:
                    self.batches += 1
                    for (_, fut), c in zip(batch, changed, strict=True):
                        if not fut.done():
                            fut.set_result(c)
            if self._closing and not self._queue:
                return
