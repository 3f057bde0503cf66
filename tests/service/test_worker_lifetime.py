"""The diagnosis workers die with the service (issue 27): ``plantcheck run`` killed with
SIGKILL leaves no worker process behind. Real processes, read from Linux's /proc."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import httpx
import pytest
from helpers import free_port
from servicehelpers import CLI, write_config

from plantcheck.service.worker_lifetime import PARENT_POLL_S
from plantcheck.storage.database import upgrade


def _children(pid: int) -> set[int]:
    """Every process below ``pid`` (Linux /proc)."""
    out: set[int] = set()
    try:
        tasks = list(Path(f"/proc/{pid}/task").iterdir())
    except FileNotFoundError:
        return out
    for task in tasks:
        try:
            kids = {int(k) for k in (task / "children").read_text().split()}
        except (FileNotFoundError, ProcessLookupError):
            continue
        out |= kids
    for k in list(out):
        out |= _children(k)
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"  # a zombie has exited; only its parent's wait is missing


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_workers_exit_when_the_service_is_killed(tmp_path: Path) -> None:
    port = free_port()
    config = write_config(tmp_path, port=port)
    upgrade(f"sqlite+aiosqlite:///{tmp_path / 'plant.db'}")
    with (tmp_path / "run.log").open("wb") as err:
        proc = subprocess.Popen([*CLI, "run", "--config", str(config)], stderr=err)
    try:
        deadline = time.monotonic() + 60
        workers: set[int] = set()
        while time.monotonic() < deadline and len(workers) < 2:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=2).status_code == 200:
                    workers = _children(proc.pid)  # 2 workers (and multiprocessing's helper)
            except httpx.TransportError:
                pass
            time.sleep(0.3)
        assert len(workers) >= 2, (tmp_path / "run.log").read_text(errors="replace")[-2000:]
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 10 * PARENT_POLL_S + 5
        while time.monotonic() < deadline and any(_alive(p) for p in workers):
            time.sleep(0.1)
        assert not [p for p in workers if _alive(p)], "workers outlived the killed service"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
