"""``GET /api/v1/loops/{id}/samples`` pages in the database (issue 45): the ``Link`` header
carries a keyset cursor, so every page costs what the first does; ``offset`` and ``limit`` are
bounded and answered 422 beyond. The app over a real SQLite store, through its ASGI interface.
"""

from __future__ import annotations

import asyncio
import re
from pathlib import Path
from typing import Any

import httpx
from test_samples_hourly import T0, _config

from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import GOOD
from plantcheck.service.app import build_app
from plantcheck.storage.database import upgrade
from plantcheck.storage.rollups import HOUR_US, roll_up
from plantcheck.storage.store import Store

N = 250
"""Samples per signal, SP, PV and OP at the same times (ties are ordered by tag)."""


def test_pages_follow_the_cursor_and_bounds_answer_422(tmp_path: Path) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    cfg = _config(url)
    # samples of 2023: kept by a retention of a century (the service's housekeeping runs at start)
    cfg = cfg.model_copy(
        update={"storage": cfg.storage.model_copy(update={"retention_days": 36500})}
    )

    async def body() -> None:
        store = await Store.open(url)
        tags = (await store.sync_config(cfg))["FIC1"].tags
        rows = [
            Sample(tags[sig], T0 + k * 60_000_000, T0, float(k), GOOD)
            for k in range(N)
            for sig in ("sp", "pv", "op")
        ]
        await store.write_samples(rows)
        await roll_up(store, T0 + 5 * HOUR_US)
        await store.close()
        app = build_app(cfg, connect=False, schedule=False)
        async with app.router.lifespan_context(app):
            transport = httpx.ASGITransport(app=app)
            async with httpx.AsyncClient(transport=transport, base_url="http://app") as client:
                frm = {"from": "2000-01-01T00:00:00Z"}
                got: list[dict[str, Any]] = []
                path: str | None = "/api/v1/loops/FIC1/samples"
                params: dict[str, Any] | None = {**frm, "limit": 37}
                while path is not None:
                    r = await client.get(path, params=params)
                    assert r.status_code == 200, r.text
                    got += r.json()
                    link = re.match(r'<([^>]+)>; rel="next"', r.headers.get("Link", ""))
                    path, params = (link.group(1), None) if link else (None, None)
                    if path:
                        assert "after=" in path and "offset=" not in path
                assert len(got) == 3 * N
                keys = [(g["time"], g["signal"]) for g in got]
                assert len(set(keys)) == 3 * N
                assert [g["time"] for g in got] == sorted(g["time"] for g in got)
                assert [g["signal"] for g in got[:3]] == ["sp", "pv", "op"]  # tag order
                # an offset page is the same as the cursor's
                r = await client.get(
                    "/api/v1/loops/FIC1/samples", params={**frm, "offset": 40, "limit": 5}
                )
                assert r.json() == got[40:45]
                hourly = await client.get(
                    "/api/v1/loops/FIC1/samples",
                    params={"resolution": "hour", "signal": "pv", "limit": 2},
                )
                assert len(hourly.json()) == 2 and "after=" in hourly.headers["Link"]
                for bad, field in (
                    ({"offset": 10_001}, "offset"),
                    ({"limit": 10_001}, "limit"),
                    ({"after": "yesterday"}, "after"),
                ):
                    r = await client.get("/api/v1/loops/FIC1/samples", params=bad)
                    assert r.status_code == 422, (bad, r.text)
                    assert r.json()["detail"][0]["loc"] == ["query", field]

    asyncio.run(body())
