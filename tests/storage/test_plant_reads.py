"""The plant-level reads on both databases (issue 49): the weekly report's aggregates (JSON
paths into the diagnoses' ``kpis``), the plant summary, every loop's latest diagnosis and the
alert outbox's round trip."""

from __future__ import annotations

import asyncio
import dataclasses

from helpers import verdict_of

from plantcheck.storage.alerts import AlertDraft, alert_counts, due_alerts, list_alerts, mark_alert
from plantcheck.storage.health_report import loop_periods
from plantcheck.storage.plant_oscillations import latest_diagnoses
from plantcheck.storage.plant_summary import plant_summary
from plantcheck.storage.results import PendingVerdict, record_verdicts
from plantcheck.storage.store import Store

HOUR = 3_600_000_000
T0 = 10**15


def test_reports_summary_and_outbox(db_url: str) -> None:
    async def run() -> None:
        store = await Store.open(db_url)
        try:
            a = await store.ensure_loop("A", signals=("pv", "op"))
            b = await store.ensure_loop("B", signals=("pv", "op"))
            draft = AlertDraft("r", "ops", 0, {"loop": "A", "state": "fault", "cause": "stiction"})
            for k, (cause, var) in enumerate([("ok", 1.0), ("ok", 3.0), ("stiction", 5.0)]):
                v = verdict_of(a, T0 + k * HOUR, cause)
                v = dataclasses.replace(
                    v, payload={"cause": cause, "kpis": {"variability_ratio": var}}
                )
                drafts = (draft,) if cause == "stiction" else ()
                await record_verdicts(store, [PendingVerdict(v, True, None, drafts)])
            await record_verdicts(store, [PendingVerdict(verdict_of(b, T0, "ok"))])
            # the period [T0 + 1 h, T0 + 3 h): A's two latest diagnoses; before: its first
            got = {p.loop: p for p in await loop_periods(store, T0 + HOUR, T0 + 3 * HOUR)}
            pa = got["A"]
            assert pa.diagnoses == 2 and pa.state_share == {"fault": 0.5, "ok": 0.5}
            assert (
                pa.kpis["variability_ratio"] == 4.0 and pa.kpis_before["variability_ratio"] == 1.0
            )
            assert [o["cause"] for o in pa.opened] == ["stiction"] and got["B"].diagnoses == 0
            s = await plant_summary(store, T0 + 3 * HOUR, span_us=2 * HOUR + HOUR // 2)
            assert dict(s.plant.now.by_state) == {"fault": 1, "ok": 1}
            assert dict(s.plant.then.by_state) == {"ok": 2}
            latest = {d.loop: d for d in await latest_diagnoses(store)}
            assert latest["A"].payload["cause"] == "stiction" and latest["B"].window_end_us == T0
            (due,) = await due_alerts(store, T0 + 3 * HOUR)
            assert (due.loop, due.state, due.payload["previous_cause"]) == ("A", "fault", "ok")
            await mark_alert(store, due.id, "delivered", 1, delivered_us=T0 + 3 * HOUR)
            assert await due_alerts(store, T0 + 3 * HOUR) == []
            assert await alert_counts(store) == {"pending": 0, "delivered": 1, "failed": 0}
            total, rows = await list_alerts(store, T0, T0 + 3 * HOUR)
            assert total == 1 and rows[0].delivered_us == T0 + 3 * HOUR
        finally:
            await store.close()

    asyncio.run(run())
