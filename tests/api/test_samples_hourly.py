"""``GET /api/v1/loops/{id}/samples?resolution=hour``: the hourly roll-ups, the long trends kept
after the samples are purged (issue 28). The app over a real SQLite store, its lifespan run and
requests sent through its ASGI interface."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import GOOD
from plantcheck.service.app import build_app
from plantcheck.service.config import Config
from plantcheck.storage.database import upgrade
from plantcheck.storage.rollups import HOUR_US, roll_up
from plantcheck.storage.store import Store

T0 = 1_700_000_000 // 3600 * HOUR_US


def _config(url: str) -> Config:
    return Config.model_validate(
        {
            # the buffer beside the database in the test's folder, never in the working folder
            "storage": {"url": url, "buffer_path": str(Path(url.split("///")[1]).parent / "b.db")},
            "source": [{"name": "plc", "protocol": "modbus", "port": 5020}],
            "loop": [
                {"id": "FIC1", "source": "plc", "type": "flow", "sp": "hr:0:float32",
                 "pv": "hr:2:float32", "op": "hr:4:float32"},
            ],
        }
    )  # fmt: skip


async def _fill(cfg: Config) -> None:
    store = await Store.open(cfg.storage.url)
    try:
        tags = (await store.sync_config(cfg))["FIC1"].tags
        rows = []
        for k in range(3 * 60):  # three hours at one a minute; the PV ramps 0..179
            t = T0 + k * 60_000_000
            rows += [Sample(tags["pv"], t, t, float(k), GOOD), Sample(tags["op"], t, t, 40.0, GOOD)]
        await store.write_samples(rows)
        await roll_up(store, T0 + 3 * HOUR_US)
        await store.purge(T0 + 3 * HOUR_US)  # retention: only each tag's newest sample stays
    finally:
        await store.close()


def test_hourly_rows_after_the_samples_are_purged(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    cfg = _config(url)
    asyncio.run(_fill(cfg))
    app = build_app(cfg, connect=False, schedule=False)

    async def get(params: dict[str, Any]) -> list[dict[str, Any]]:
        async with app.router.lifespan_context(app):
            transport = httpx.ASGITransport(app=app)
            async with httpx.AsyncClient(transport=transport, base_url="http://app") as client:
                r = await client.get("/api/v1/loops/FIC1/samples", params=params)
                assert r.status_code == 200, r.text
                body: list[dict[str, Any]] = r.json()
                return body

    hourly = asyncio.run(get({"resolution": "hour", "signal": "pv"}))
    assert [(h["count"], h["value"], h["min"], h["max"]) for h in hourly] == [
        (60, 29.5, 0.0, 59.0),
        (60, 89.5, 60.0, 119.0),
        (60, 149.5, 120.0, 179.0),
    ]
    assert hourly[0]["time"] == "2023-11-14T22:00:00.000Z" and hourly[0]["received_at"] is None
    raw = asyncio.run(get({"signal": "pv", "from": "2023-11-14T22:00:00Z"}))
    # the purge kept the newest sample only (and the service marks its restart there)
    assert {r["time"] for r in raw} == {"2023-11-15T00:59:00.000Z"}
    assert all(r["count"] is None for r in raw)
