"""The plant, worst first (issue 49 item 2): ``GET /loops`` sorts by priority and filters by
state, cause, type, area and unit; the page's table does the same and shows the indices;
``GET /plant/summary`` counts loops by state and cause, per area, now and a week before; the
plant page shows the summary and the latest plant-wide oscillation groups
(``GET /plant/oscillations``). The app over a real SQLite store, through its ASGI interface."""

from __future__ import annotations

import asyncio
import dataclasses
import re
import sqlite3
import time
from pathlib import Path
from typing import Any

import httpx
from helpers import verdict_of

from plantcheck.service.app import build_app
from plantcheck.service.config import Config
from plantcheck.storage.database import upgrade
from plantcheck.storage.plant_oscillations import KEEP, record_plant_oscillations
from plantcheck.storage.results import record_verdict
from plantcheck.storage.store import Store

DAY_US = 86_400_000_000
LOOPS = [
    # id, type, area, criticality, cause a week ago, cause now, kpis now
    ("FIC1", "flow", "north", 5, "ok", "stiction", {"variability_ratio": 2.0}),
    ("FIC2", "flow", "north", 1, "ok", "stiction", {}),
    ("LIC1", "level", "south", 3, "ok", "ok", {"variability_ratio": 5.0, "harris_index": 0.2}),
    ("TIC1", "temperature", "south", None, "ok", "ok", {"variability_ratio": 1.0}),
    ("PIC1", "pressure", "", 4, None, "sluggish_tuning", {"service_factor": 0.5}),
]


GROUP = {
    "period_s": 152.0,
    "loops": ["FIC1", "FIC2", "LIC1"],
    "source": "FIC1",
    "evidence": ["FIC1: its valve (cause stiction, S 2.00 %)", "LIC1 lags FIC1 by 12.0 s"],
    "lags_s": {"FIC2": 3.0, "LIC1": 12.0},
}


def _config(tmp_path: Path) -> Config:
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    return Config.model_validate(
        {
            "storage": {"url": url, "buffer_path": str(tmp_path / "b.db")},
            "source": [{"name": "plc", "protocol": "modbus", "port": 5020}],
            "loop": [
                {"id": i, "source": "plc", "type": t, "pv": f"hr:{4 * k}:float32",
                 "op": f"hr:{4 * k + 2}:float32", "area": area, "unit": f"{area}-1" if area else "",
                 **({"criticality": crit} if crit else {})}
                for k, (i, t, area, crit, *_) in enumerate(LOOPS)
            ],
        }
    )  # fmt: skip


async def _fill(cfg: Config, now_us: int) -> None:
    store = await Store.open(cfg.storage.url)
    try:
        rows = await store.sync_config(cfg)
        for name, _, _, _, before, cause, kpis in LOOPS:
            if before is not None:
                await record_verdict(store, verdict_of(rows[name], now_us - 8 * DAY_US, before))
            v = verdict_of(
                rows[name], now_us - 60_000_000, cause, S=2.0 if cause == "stiction" else None
            )
            await record_verdict(
                store, dataclasses.replace(v, payload={"cause": cause, "kpis": kpis})
            )
        for k in range(KEEP + 3):  # passes beyond the latest KEEP are dropped
            await record_plant_oscillations(store, now_us - (KEEP + 3 - k) * 1000, [])
        await record_plant_oscillations(store, now_us, [GROUP])
    finally:
        await store.close()


async def _get(cfg: Config, paths: list[str]) -> list[Any]:
    app = build_app(cfg, connect=False, schedule=False)
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://app") as client:
            out = []
            for p in paths:
                r = await client.get(p)
                assert r.status_code == 200, (p, r.text)
                csv = "format=csv" in p
                out.append(r.json() if p.startswith("/api") and not csv else r.text)
            return out


def test_worst_first_filters_and_the_plant_summary(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    asyncio.run(_fill(cfg, time.time_ns() // 1000))
    (
        by_id,
        worst,
        north,
        sticky,
        levels,
        unit,
        summary,
        page,
        page_south,
        oscillations,
        plant_page,
        weekly,
        weekly_page,
        maintenance,
        maintenance_page,
        weekly_csv,
    ) = asyncio.run(
        _get(
            cfg,
            [
                "/api/v1/loops",
                "/api/v1/loops?sort=priority",
                "/api/v1/loops?area=north",
                "/api/v1/loops?cause=stiction&sort=priority",
                "/api/v1/loops?type=level",
                "/api/v1/loops?unit=south-1&state=ok",
                "/api/v1/plant/summary",
                "/",
                "/?area=south&sort=priority",
                "/api/v1/plant/oscillations",
                "/plant",
                "/api/v1/reports/weekly",
                "/weekly",
                "/api/v1/reports/maintenance",
                "/maintenance",
                "/api/v1/reports/weekly?format=csv",
            ],
        )
    )
    # the weekly report: a week of one diagnosis per loop, against the week before
    week = {lp["loop"]: lp for lp in weekly["loops"]}
    fic1 = week["FIC1"]
    assert fic1["diagnoses"] == 1 and fic1["hours_in_state"] == {"fault": 168.0}
    assert fic1["kpis"]["variability_ratio"] == 2.0 and fic1["kpis_before"]["harris_index"] is None
    assert [a["cause"] for a in fic1["opened"]] == ["stiction"] and fic1["closed"] == []
    assert week["PIC1"]["kpis"]["service_factor"] == 0.5
    assert re.findall(r'<tr class="state-\w+" data-loop="(\w+)"', weekly_page) == sorted(week)
    assert weekly_csv.splitlines()[0].startswith("loop,area,criticality,state,cause,diagnoses")
    assert len(weekly_csv.splitlines()) == 1 + len(LOOPS)
    # the maintenance report: the two sticky valves, with the indices of their latest window
    assert sorted(v["loop"] for v in maintenance["valves"]) == ["FIC1", "FIC2"]
    assert all(v["cause"] == "stiction" and v["current_S"] == 2.0 for v in maintenance["valves"])
    assert 'data-loop="FIC1"' in maintenance_page and 'data-loop="TIC1"' not in maintenance_page
    assert [{k: g[k] for k in GROUP} for g in oscillations] == [GROUP]
    with sqlite3.connect(tmp_path / "store.db") as con:
        assert con.execute("SELECT count(*) FROM plant_oscillations").fetchone()[0] == KEEP
    assert re.findall(r'class="oscillation-group" data-source="(\w+)"', plant_page) == ["FIC1"]
    assert "whole plant" in plant_page and 'data-area="north"' in plant_page
    assert [r["id"] for r in by_id] == sorted(r[0] for r in LOOPS)
    # stiction (fault) critical 5, then sluggish (warning) 4 half in manual, then the level
    # 5× its normal though ok, then the sticky valve of criticality 1, then the healthy loop
    assert [r["id"] for r in worst] == ["FIC1", "PIC1", "LIC1", "FIC2", "TIC1"]
    assert worst[0]["priority"] == 77.5  # 100 · 5/5 · (0.7 · 1 + 0.3 · (2 − 1)/4)
    first = worst[0]
    assert (first["area"], first["unit"], first["criticality"]) == ("north", "north-1", 5)
    assert first["kpis"]["variability_ratio"] == 2.0
    assert next(r for r in by_id if r["id"] == "TIC1")["criticality"] is None
    assert [r["id"] for r in north] == ["FIC1", "FIC2"]
    assert [r["id"] for r in sticky] == ["FIC1", "FIC2"]
    assert [r["id"] for r in levels] == ["LIC1"]
    assert [r["id"] for r in unit] == ["LIC1", "TIC1"]

    plant = summary["plant"]
    assert plant["now"]["by_state"] == {"fault": 2, "warning": 1, "ok": 2}
    assert plant["then"]["by_state"] == {"ok": 4, "unknown": 1}
    assert plant["change_by_state"] == {"fault": 2, "ok": -2, "unknown": -1, "warning": 1}
    assert plant["change_by_cause"] == {"ok": -2, "sluggish_tuning": 1, "stiction": 2}
    areas = {a["area"]: a for a in summary["areas"]}
    assert set(areas) == {"north", "south"}
    assert areas["north"]["now"]["by_cause"] == {"stiction": 2}
    assert areas["south"]["change_by_state"] == {}

    # the page: the worst first by default, the indices shown, the filters the API's
    rows = re.findall(r'data-loop="(\w+)"', page)
    assert rows == ["FIC1", "PIC1", "LIC1", "FIC2", "TIC1"]
    assert re.findall(r'data-loop="(\w+)"', page_south) == ["LIC1", "TIC1"]
    assert "2 of 5 loops" in page_south
    lic = page.split('data-loop="LIC1"')[1].split("</tr>")[0]
    assert re.search(r'data-key="harris"[^>]*>0\.20<', lic), lic
    assert re.search(r'data-key="var"[^>]*>5\.0<', lic), lic
    pic = page.split('data-loop="PIC1"')[1].split("</tr>")[0]
    assert re.search(r'data-key="sf"[^>]*>50<', pic), pic
    assert '<option value="south">south</option>' in page
    assert '<option value="south" selected>south</option>' in page_south
