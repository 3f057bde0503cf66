"""Verdicts committed in batches keep the one-at-a-time semantics: history, state, ``since``,
actions and S/J per loop, a loop's verdicts applied in order, errors reach every waiting job."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest
from helpers import T0, verdict_of

from plantcheck.service.config import Config
from plantcheck.service.scheduler import DiagnosisScheduler, LoopJobState
from plantcheck.storage.results import (
    PendingVerdict,
    Verdict,
    active_actions,
    diagnosis_history,
    loop_statuses,
    stiction_history,
)
from plantcheck.storage.store import LoopRow, Store
from plantcheck.storage.verdict_writer import VerdictWriter


def _config(n: int) -> Config:
    return Config.model_validate(
        {
            "source": [{"name": "s", "protocol": "opcua", "url": "opc.tcp://127.0.0.1:1/"}],
            "loop": [
                {"id": f"L{i}", "source": "s", "pv": f"ns=2;s=L{i}.PV", "op": f"ns=2;s=L{i}.OP"}
                for i in range(n)
            ],
        }
    )


def _verdict(row: LoopRow, at: int, cause: str, S: float | None = None) -> Verdict:
    return verdict_of(row, at, cause, S, None if S is None else 0.5)


def test_batched_verdicts(db_url: str) -> None:
    async def body() -> None:
        store = await Store.open(db_url)
        writer = VerdictWriter(store, linger_s=0.05)
        try:
            rows = await store.sync_config(_config(5))
            first = [
                writer.write(PendingVerdict(_verdict(rows[f"L{i}"], T0, "stiction", 2.0 + i)))
                for i in range(5)
            ]
            # L0's second verdict (a new cause, adopted) waits for the next batch
            later = writer.write(PendingVerdict(_verdict(rows["L0"], T0 + 10, "ok"), True, T0 + 5))
            changed = await asyncio.gather(*first, later)
            assert changed == [True] * 6 and writer.batches == 2
            # the same cause again: no change, the action's text follows the new S
            kept = await writer.write(PendingVerdict(_verdict(rows["L1"], T0 + 20, "stiction", 9)))
            # a new cause not yet confirmed: history only
            held = await writer.write(
                PendingVerdict(_verdict(rows["L2"], T0 + 20, "ok"), adopt=False)
            )
            assert (kept, held) == (False, False)
            st = {s.id: s for s in await loop_statuses(store)}
            assert (st["L0"].cause, st["L0"].since_us, st["L0"].last_diagnosis_us) == (
                "ok",
                T0 + 5,
                T0 + 10,
            )
            assert (st["L1"].cause, st["L1"].since_us, st["L1"].S) == ("stiction", T0, 9.0)
            assert (st["L2"].cause, st["L2"].last_diagnosis_us) == ("stiction", T0 + 20)
            acts = {a["loop"]: a for a in await active_actions(store)}
            assert "L0" not in acts and set(acts) == {"L1", "L2", "L3", "L4"}
            assert "9.0" in acts["L1"]["text"] and acts["L1"]["since_us"] == T0
            total, _ = await diagnosis_history(store, rows["L0"])
            assert total == 2
            assert [e.S for e in (await stiction_history(store))["L1"]] == [3.0, 9.0]
        finally:
            await writer.close()
            await store.close()

    asyncio.run(body())


def test_store_error_reaches_each_job(tmp_path: Any) -> None:
    async def body() -> None:
        url = f"sqlite+aiosqlite:///{tmp_path / 'none.db'}"
        store = await Store.open(url, check=False)  # no schema: every write fails
        writer = VerdictWriter(store, linger_s=0.01)
        row, other = LoopRow(1, "L1", "flow", "s", {}), LoopRow(2, "L2", "flow", "s", {})
        try:
            results = await asyncio.gather(
                writer.write(PendingVerdict(_verdict(row, T0, "ok"))),
                writer.write(PendingVerdict(_verdict(other, T0, "ok"))),
                return_exceptions=True,
            )
            assert all(isinstance(r, Exception) and "no such table" in str(r) for r in results)
        finally:
            await writer.close()
            await store.close()
        with pytest.raises(RuntimeError, match="closed"):
            await writer.write(PendingVerdict(_verdict(row, T0, "ok")))

    asyncio.run(body())


def test_unreliable_estimates_back_off() -> None:
    """An S/J estimate that fails the reliability rules is retried after one period, then
    twice as long each time up to ``quantify_every_s``; a reliable one waits the full time.
    While the window is still filling, every run tries again (each window holds more periods)
    and the back-off starts from one period once it is full."""
    sched = DiagnosisScheduler.__new__(DiagnosisScheduler)
    sched.quantify_every_s = 3600.0
    st = LoopJobState()
    unreliable = {"stiction": {"S": None, "quantification": {"reliable": False}}}
    waits = []
    for filling in (True, True, True, False, False, False, False, False):
        t = time.monotonic()
        sched._schedule_quantification(st, unreliable, 600.0, filling)
        waits.append(round(st.quantify_due - t))
    assert waits == [600, 600, 600, 600, 1200, 2400, 3600, 3600]
    sched._schedule_quantification(st, {"stiction": {"S": 2.0}}, 600.0, False)
    assert st.quantify_backoff_s == 0 and st.quantify_due > time.monotonic() + 3599
    before = st.quantify_due
    sched._schedule_quantification(st, {"cause": "ok"}, 600.0, True)  # no attempt: unchanged
    assert st.quantify_due == before
