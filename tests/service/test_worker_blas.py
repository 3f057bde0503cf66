"""Diagnosis workers and the command line run numpy with one BLAS thread each (OpenBLAS's
threads only spin on the chain's small matrix products: 27-30 ms of CPU per 1-h window instead
of 17)."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from pathlib import Path

import pytest

from plantcheck.service.blas_threads import BLAS_THREAD_VARIABLES
from plantcheck.service.config import Config
from plantcheck.service.runtime import schedules_of
from plantcheck.service.scheduler import DiagnosisScheduler
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


DIAGNOSE_AND_COUNT_THREADS = """
import os, sys
from plantcheck.service.cli import main
sys.argv = ["plantcheck", "diagnose", sys.argv[1]]
try:
    main()
except SystemExit as end:
    assert end.code in (0, None), end.code
assert "numpy" in sys.modules
print(len(os.listdir("/proc/self/task")))
"""


def test_the_command_line_diagnoses_on_one_thread(tmp_path: Path) -> None:
    """The console script's entry point, with no thread variable set: numpy was loaded by the
    diagnosis, after the entry point asked for one BLAS thread, so the process has no thread
    but its own (OpenBLAS starts one per core at load otherwise)."""
    record = tmp_path / "loop.csv"
    rows = "".join(f"{k},50,{50 + (k // 60) % 2:.1f},{40 + (k % 60) / 6:.2f}\n" for k in range(600))
    record.write_text("t,sp,pv,op\n" + rows, encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    done = subprocess.run(
        [sys.executable, "-c", DIAGNOSE_AND_COUNT_THREADS, str(record)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "1"
