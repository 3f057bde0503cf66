"""The API while PostgreSQL is down (issue 27): every read route answers 503 with Retry-After
(it answered 500 with a traceback in the log), and answers again once the database is back;
the outage is one line in the log, not one per request (issue 45).
Real processes: a PostgreSQL cluster stopped and started, a ``plantcheck run``."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from helpers import free_port
from pgcluster import PgCluster

CLI = [sys.executable, "-m", "plantcheck.service.cli"]


def _wait(url: str, status: int, timeout_s: float = 60.0) -> httpx.Response:
    deadline = time.monotonic() + timeout_s
    last: httpx.Response | None = None
    while time.monotonic() < deadline:
        try:
            last = httpx.get(url, timeout=10)
            if last.status_code == status:
                return last
        except httpx.TransportError:
            pass
        time.sleep(0.5)
    pytest.fail(f"{url} never answered {status} (last: {last and last.status_code})")


@pytest.mark.slow
def test_api_answers_503_while_postgresql_is_down(pg_cluster: PgCluster, tmp_path: Path) -> None:
    port = free_port()
    cfg = tmp_path / "plantcheck.toml"
    cfg.write_text(
        f'[storage]\nurl = "{pg_cluster.url}"\nbuffer_path = "{tmp_path / "buf.db"}"\n\n'
        f"[api]\nport = {port}\n\n"
        f'[[source]]\nname = "plc"\nprotocol = "modbus"\nport = {free_port()}\n\n'
        '[[loop]]\nid = "FIC1"\ntype = "flow"\nsource = "plc"\n'
        'pv = "hr:22:float32"\nop = "hr:24:float32"\n',
        encoding="utf-8",
    )
    err = (tmp_path / "stderr.txt").open("wb")
    proc = subprocess.Popen([*CLI, "run", "--config", str(cfg), "--migrate"], stderr=err)
    base = f"http://127.0.0.1:{port}"
    try:
        _wait(f"{base}/readyz", 200)
        assert httpx.get(f"{base}/api/v1/loops", timeout=10).status_code == 200
        pg_cluster.stop()
        try:
            for path in ("/api/v1/loops/FIC1", "/api/v1/loops/FIC1/diagnoses"):
                r = _wait(base + path, 503, timeout_s=30)
                assert r.headers["Retry-After"] == "30"
                assert "store is unreachable" in r.json()["detail"]
            # the loop table is served from memory while it lasts, never as a 500; its failed
            # refreshes are logged once for the outage, not once per request
            for _ in range(10):
                assert httpx.get(f"{base}/api/v1/loops", timeout=10).status_code in (200, 503)
                time.sleep(1.1)
        finally:
            pg_cluster.start()
        _wait(f"{base}/api/v1/loops", 200)
    finally:
        proc.terminate()
        proc.wait(30)
        err.close()
    log = (tmp_path / "stderr.txt").read_text(errors="replace")
    assert "Traceback" not in log, log[-2000:]
    assert "never retrieved" not in log, log[-2000:]
    assert log.count("loop table: cannot refresh") <= 1, log[-2000:]
