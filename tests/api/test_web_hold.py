"""The loop page holds a loop's signals as its diagnosis does: every signal of an OPC UA source
(reported on change only: a stuck valve's MV is one sample), SP and mode of a Modbus source.
The app over a real SQLite store, its lifespan run and requests sent through its ASGI interface."""

from __future__ import annotations

import asyncio
import json
import re
from pathlib import Path

import httpx
from helpers import T0

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import GOOD
from plantcheck.service.app import build_app
from plantcheck.service.config import Config
from plantcheck.storage.database import upgrade
from plantcheck.storage.store import Store


def _config(url: str) -> Config:
    loop = {"sp": "SP", "pv": "PV", "op": "OP", "mv": "MV"}
    return Config.model_validate(
        {
            # the buffer in the test's folder, never in the working folder
            "storage": {"url": url, "buffer_path": str(Path(url.split("///")[1]).parent / "b.db")},
            "source": [
                {"name": "ua", "protocol": "opcua", "url": "opc.tcp://127.0.0.1:4840/"},
                {"name": "plc", "protocol": "modbus", "port": 5020},
            ],
            "loop": [
                {"id": "UA1", "source": "ua", "type": "flow",
                 **{k: f"ns=2;s=UA1.{v}" for k, v in loop.items()}},
                {"id": "MB1", "source": "plc", "type": "flow", "sp": "hr:0:float32",
                 "pv": "hr:2:float32", "op": "hr:4:float32", "mv": "hr:6:float32"},
            ],
        }
    )  # fmt: skip


async def _fill(cfg: Config) -> None:
    store = await Store.open(cfg.storage.url)
    try:
        rows = []
        for row in (await store.sync_config(cfg)).values():
            tags = row.tags
            rows += [Sample(tags["sp"], T0, T0, 50.0, GOOD), Sample(tags["mv"], T0, T0, 37.5, GOOD)]
            for k in range(600):
                t = T0 + k * 1_000_000
                rows += [Sample(tags[s], t, t, 40.0 + k % 5, GOOD) for s in ("pv", "op")]
        await store.write_samples(rows)
    finally:
        await store.close()


async def _plot(client: httpx.AsyncClient, loop: str) -> dict[str, list[float | None]]:
    page = await client.get(f"/loop/{loop}")
    assert page.status_code == 200
    m = re.search(r'<script id="plot-data" type="application/json">(.*?)</script>', page.text)
    assert m is not None
    data: dict[str, list[float | None]] = json.loads(m.group(1))
    return data


def test_loop_page_holds_signals_as_the_diagnosis_does(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    cfg = _config(url)
    asyncio.run(_fill(cfg))
    app = build_app(cfg, connect=False, schedule=False)

    async def pages() -> tuple[dict[str, list[float | None]], ...]:
        async with app.router.lifespan_context(app):
            transport = httpx.ASGITransport(app=app)
            async with httpx.AsyncClient(transport=transport, base_url="http://app") as client:
                return await _plot(client, "UA1"), await _plot(client, "MB1")

    ua, mb = asyncio.run(pages())
    # the page shows the last hour up to the newest sample: the data are its last 600 s
    k = next(i for i, t in enumerate(ua["t"]) if t >= T0 / 1e6)
    assert set(ua["mv"][k:]) == {37.5} and set(ua["sp"][k:]) == {50.0}  # held from one sample
    assert set(mb["sp"][k:]) == {50.0}  # SP held on a polled source too
    assert set(mb["mv"][k + 1 :]) == {None}  # polled MV: its one sample, then gaps
