"""Diagnosis workers run numpy with one BLAS thread each (OpenBLAS's threads only spin on the
chain's small matrix products: 27-30 ms of CPU per 1-h window instead of 17)."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest

from plantcheck.service.config import Config
from plantcheck.service.runtime import schedules_of
from plantcheck.service.scheduler import BLAS_THREAD_VARIABLES, DiagnosisScheduler
from plantcheck.storage.database import upgrade
from plantcheck.storage.store import Store

CONFIG = Config.model_validate(
    {
        "source": [{"name": "s", "protocol": "opcua", "url": "opc.tcp://127.0.0.1:1/"}],
        "loop": [{"id": "TIC1", "source": "s", "pv": "ns=2;s=T.PV", "op": "ns=2;s=T.OP"}],
    }
)


def blas_settings() -> dict[str, str | None]:
    """Run in a worker: what its BLAS was told at load."""
    return {name: os.environ.get(name) for name in BLAS_THREAD_VARIABLES}


@pytest.mark.parametrize("preset", [None, "2"])
def test_workers_get_one_blas_thread_unless_the_environment_says(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, preset: str | None
) -> None:
    """On SQLite alone: the store only gives the scheduler its loops."""
    db_url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(db_url)
    for name in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    if preset is not None:
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", preset)

    async def body() -> dict[str, str | None]:
        store = await Store.open(db_url)
        sched = DiagnosisScheduler(store, schedules_of(CONFIG), 1)
        try:
            await store.sync_config(CONFIG)
            await sched.open_pool()
            assert sched._pool is not None
            return await asyncio.get_running_loop().run_in_executor(sched._pool, blas_settings)
        finally:
            await sched.stop()
            await store.close()

    seen = asyncio.run(body())
    assert seen["OPENBLAS_NUM_THREADS"] == (preset or "1")
    assert seen["OMP_NUM_THREADS"] == "1" and seen["MKL_NUM_THREADS"] == "1"
