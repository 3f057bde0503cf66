"""A collector killed with SIGKILL and started again, on real processes: ``plantcheck simulate``
serving Modbus TCP, ``plantcheck ingest`` writing one loop into a real SQLite file (issue 27).
Shared by ``tests/service/test_restart_gaps.py``, which checks the gap marker, and
``benchmarks/crash_loss.py``, which times what a crash loses: a clock is measured there, not
asserted in a test that a loaded machine may run slowly."""

from __future__ import annotations

import signal
import sqlite3
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from helpers import free_port

CLI = [sys.executable, "-m", "plantcheck.service.cli"]
Row = tuple[int, float | None, int]
"""A stored sample: time (µs since the epoch), value (None for a gap marker), status code."""
WAIT_S = 30.0
"""How long the drill waits for the samples it needs before it calls the collector stuck, s."""
COMMIT_INTERVAL_S = 0.2
POLL_INTERVAL_S = 0.5
"""The collector's ``storage.commit_interval_s`` and its source's ``poll_interval_s``, s: the
two terms of the README's loss bound."""


@dataclass(frozen=True)
class CrashDrill:
    """What one drill saw of FIC102.pv: the rows stored when the first collector had died
    (``killed``), all rows once the second had stored 8 more (``rows``), and ``lost_s``: the
    time from the newest stored sample to the SIGKILL, s (the README's loss bound on a crash)."""

    killed: list[Row]
    rows: list[Row]
    lost_s: float


def _pv_rows(db: Path) -> list[Row]:
    with sqlite3.connect(db) as con:
        return con.execute(
            "SELECT s.ts_us, s.value, s.status FROM samples s JOIN tags t ON s.tag_id = t.id "
            "JOIN loops l ON t.loop_id = l.id WHERE l.name = 'FIC102' AND t.signal = 'pv' "
            "ORDER BY s.ts_us"
        ).fetchall()


def _wait_rows(db: Path, at_least: int) -> list[Row]:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        if db.exists():
            try:
                rows = _pv_rows(db)
            except sqlite3.OperationalError:  # tables not there yet
                rows = []
            if len(rows) >= at_least:
                return rows
        time.sleep(0.3)
    raise TimeoutError(f"fewer than {at_least} FIC102.pv samples stored after {WAIT_S:g} s")


def crash_drill(folder: Path, dead_s: float = 3.0) -> CrashDrill:
    """Start the simulator and a collector storing into ``folder``, SIGKILL the collector once
    10 samples are stored, leave it dead ``dead_s`` s, start it again until 8 more are stored,
    stop everything."""
    modbus, admin = free_port(), free_port()
    sim = subprocess.Popen(
        [*CLI, "simulate", "--modbus", f"127.0.0.1:{modbus}", "--opcua", "off",
         "--admin", f"127.0.0.1:{admin}", "--quiet"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    db = folder / "store.db"
    cfg = folder / "plantcheck.toml"
    cfg.write_text(
        f'[storage]\nurl = "sqlite+aiosqlite:///{db}"\nbuffer_path = "{folder / "buf.db"}"\n'
        f"commit_interval_s = {COMMIT_INTERVAL_S}\n\n"
        f'[[source]]\nname = "plc"\nprotocol = "modbus"\nport = {modbus}\n'
        f"poll_interval_s = {POLL_INTERVAL_S}\n\n"
        '[[loop]]\nid = "FIC102"\ntype = "flow"\nsource = "plc"\n'
        'sp = "hr:20:float32"\npv = "hr:22:float32"\nop = "hr:24:float32"\n',
        encoding="utf-8",
    )
    collectors: list[subprocess.Popen[bytes]] = []
    try:
        upgraded = subprocess.run(
            [*CLI, "db", "upgrade", "--config", str(cfg)], stdout=subprocess.DEVNULL
        )
        if upgraded.returncode != 0:
            raise RuntimeError(f"plantcheck db upgrade exited {upgraded.returncode}")

        def collect() -> subprocess.Popen[bytes]:
            proc = subprocess.Popen([*CLI, "ingest", "--config", str(cfg)],
                                    stderr=subprocess.DEVNULL)  # fmt: skip
            collectors.append(proc)
            return proc

        first = collect()
        _wait_rows(db, 10)
        first.send_signal(signal.SIGKILL)
        killed_at_us = time.time_ns() // 1000
        first.wait(10)
        killed = _pv_rows(db)
        time.sleep(dead_s)
        second = collect()
        rows = _wait_rows(db, len(killed) + 8)
        second.terminate()
        second.wait(30)
        return CrashDrill(killed, rows, (killed_at_us - killed[-1][0]) / 1e6)
    finally:
        for proc in [*collectors, sim]:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
