"""A service stopped while a diagnosis is under way lets it finish and logs no error."""

from __future__ import annotations

import asyncio
import logging

import pytest

from plantcheck.service.config import Config
from plantcheck.service.scheduler import DiagnosisScheduler, LoopSchedule
from plantcheck.storage.store import Store


class _SlowScheduler(DiagnosisScheduler):
    """A diagnosis that takes half a second (the stop must wait for it, not cancel it)."""

    started: asyncio.Event
    finished: list[str]

    async def _diagnose(self, sched: LoopSchedule) -> str:
        self.started.set()
        await asyncio.sleep(0.5)
        self.finished.append(sched.name)
        return "ok"


def test_stop_lets_running_diagnoses_finish(db_url: str, caplog: pytest.LogCaptureFixture) -> None:
    config = Config.model_validate(
        {
            "source": [{"name": "s", "protocol": "opcua", "url": "opc.tcp://127.0.0.1:1/"}],
            "loop": [{"id": "L0", "source": "s", "pv": "ns=2;s=L0.PV", "op": "ns=2;s=L0.OP"}],
        }
    )

    async def body() -> None:
        store = await Store.open(db_url)
        try:
            await store.sync_config(config)
            sched = _SlowScheduler(store, [LoopSchedule("L0", "flow", 600.0, 60.0)], workers=1)
            sched.started, sched.finished = asyncio.Event(), []
            await sched.start()
            await asyncio.wait_for(sched.started.wait(), 30)
            await sched.stop()
            assert sched.finished == ["L0"]
        finally:
            await store.close()

    with caplog.at_level(logging.INFO):
        asyncio.run(body())
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert not errors
