"""The service's metrics as a scraper reads them (issue 47): the received rate at any scrape
pace, the buffer depth that counts only what the store did not take."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from helpers import one_loop_config

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import GOOD
from plantcheck.service.metrics import ServiceMetrics
from plantcheck.storage.database import upgrade
from plantcheck.storage.store import Store
from plantcheck.storage.writer import SampleWriter


def test_the_rate_is_not_zero_when_scrapes_are_a_minute_or_more_apart() -> None:
    m = ServiceMetrics()
    t0 = m._received[0][0]
    for k in range(1, 6):  # 1,000 samples/s, scraped every 90 s
        m.received(90_000)
        # the clock's magnitude leaves a rounding error in the differences: 1000.0000000000202
        assert m.sample_rate(now=t0 + 90.0 * k) == pytest.approx(1000.0, rel=1e-9)
    m.received(15_000)  # then every 15 s
    assert m.sample_rate(now=t0 + 465.0) > 900.0


def test_the_buffer_depth_is_zero_while_the_store_keeps_up(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)

    async def run() -> None:
        store = await Store.open(url)
        tag = (await store.sync_config(one_loop_config()))["FIC1"].tags["pv"]
        w = SampleWriter(store, tmp_path / "buffer.db")
        w.put([Sample(tag, k, k, 1.0, GOOD) for k in range(1500)])  # this second's batch
        assert w.depth == 1500 and w.backlog == 0
        await w.stop()
        await store.close()

    asyncio.run(run())
