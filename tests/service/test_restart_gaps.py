"""A crashed collector leaves no unmarked gap (issue 27): ``plantcheck ingest`` killed with
SIGKILL and started again stores a gap marker right after each tag's last sample, so the
windows never hold a value across the dead time. Real processes: the simulator and the
collector, a real SQLite file."""

from __future__ import annotations

import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import free_port

from plantcheck.core.status_codes import BAD_NO_COMMUNICATION

CLI = [sys.executable, "-m", "plantcheck.service.cli"]
Row = tuple[int, float | None, int]


def _pv_rows(db: Path) -> list[Row]:
    with sqlite3.connect(db) as con:
        return con.execute(
            "SELECT s.ts_us, s.value, s.status FROM samples s JOIN tags t ON s.tag_id = t.id "
            "JOIN loops l ON t.loop_id = l.id WHERE l.name = 'FIC102' AND t.signal = 'pv' "
            "ORDER BY s.ts_us"
        ).fetchall()


def _wait_rows(
    db: Path, at_least: int, timeout_s: float = 30.0
) -> list[tuple[int, float | None, int]]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if db.exists():
            try:
                rows = _pv_rows(db)
            except sqlite3.OperationalError:  # tables not there yet
                rows = []
            if len(rows) >= at_least:
                return rows
        time.sleep(0.3)
    pytest.fail(f"fewer than {at_least} FIC102.pv samples stored after {timeout_s:g} s")


@pytest.mark.slow
def test_collector_killed_and_restarted_marks_the_dead_time(tmp_path: Path) -> None:
    modbus, admin = free_port(), free_port()
    sim = subprocess.Popen(
        [*CLI, "simulate", "--modbus", f"127.0.0.1:{modbus}", "--opcua", "off",
         "--admin", f"127.0.0.1:{admin}", "--quiet"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    db = tmp_path / "store.db"
    cfg = tmp_path / "plantcheck.toml"
    cfg.write_text(
        f'[storage]\nurl = "sqlite+aiosqlite:///{db}"\nbuffer_path = "{tmp_path / "buf.db"}"\n'
        "commit_interval_s = 0.2\n\n"
        f'[[source]]\nname = "plc"\nprotocol = "modbus"\nport = {modbus}\n'
        "poll_interval_s = 0.5\n\n"
        '[[loop]]\nid = "FIC102"\ntype = "flow"\nsource = "plc"\n'
        'sp = "hr:20:float32"\npv = "hr:22:float32"\nop = "hr:24:float32"\n',
        encoding="utf-8",
    )
    collectors: list[subprocess.Popen[bytes]] = []
    try:
        assert subprocess.run([*CLI, "db", "upgrade", "--config", str(cfg)]).returncode == 0

        def collect() -> subprocess.Popen[bytes]:
            proc = subprocess.Popen([*CLI, "ingest", "--config", str(cfg)],
                                    stderr=subprocess.DEVNULL)  # fmt: skip
            collectors.append(proc)
            return proc

        first = collect()
        before = _wait_rows(db, 10)
        first.send_signal(signal.SIGKILL)
        killed_at_us = time.time_ns() // 1000
        first.wait(10)
        killed = _pv_rows(db)
        assert killed[-1][2] != BAD_NO_COMMUNICATION  # a crash writes nothing on its way out
        # the loss bound (README): what arrived since the last commit (commit_interval_s 0.2)
        # plus the poll under way (0.5 s); 2 s more for a loaded machine
        lost_s = (killed_at_us - killed[-1][0]) / 1e6
        assert lost_s < 0.2 + 0.5 + 2.0, lost_s
        time.sleep(3.0)
        second = collect()
        rows = _wait_rows(db, len(killed) + 8)
        second.terminate()
        second.wait(30)
        last = killed[-1][0]
        marker = [r for r in rows if r[0] == last + 1]
        assert marker and marker[0][2] == BAD_NO_COMMUNICATION and marker[0][1] is None, rows[-12:]
        resumed = [r for r in rows if r[0] > last + 1 and r[2] != BAD_NO_COMMUNICATION]
        assert resumed and resumed[0][0] - last > 2_000_000  # the dead time lies inside the gap
        assert len(before) >= 10
    finally:
        for proc in [*collectors, sim]:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
