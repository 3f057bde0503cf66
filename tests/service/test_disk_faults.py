"""Disk faults with real processes (issue 45): ``plantcheck simulate`` serves Modbus TCP and
OPC UA, ``plantcheck run`` collects one loop from each into SQLite on a small real filesystem
(``smalldisk``: a tmpfs, which needs root; skipped with that reason without it), and the test
fills that filesystem, then frees it; or on a FUSE pass-through (``readonlyfs``) that the test
turns read-only, then writable again.

Three faults: the database and the durable buffer on the one disk that fills (samples wait in
memory), the same disk turned read-only, and the database's disk full with the buffer on
another (the buffer takes them). For each: ``/readyz`` answers 503 naming storage within 5 s,
``GET /api/v1/storage`` says where the samples are, writing resumes within 10 s of the disk
recovering, and the stored history of both protocols has no hole that a gap marker does not
cover.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
from smalldisk import readonly_disk, small_disk

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from soak import LOOPS, Drill, drill


def _poll(d: Drill, until: Any, timeout_s: float) -> tuple[float, dict[str, Any]]:
    """Seconds until ``until(readyz body, status, storage body)`` held, and the last bodies."""
    t0 = time.monotonic()
    last: dict[str, Any] = {}
    while time.monotonic() - t0 < timeout_s:
        try:
            r = httpx.get(f"{d.api_url}/readyz", timeout=2)
            s = httpx.get(f"{d.api_url}/api/v1/storage", timeout=2).json()
            last = {"readyz": r.json(), "status": r.status_code, "storage": s}
            if until(r.json(), r.status_code, s):
                return time.monotonic() - t0, last
        except httpx.HTTPError as exc:
            last = {"error": repr(exc)}
        time.sleep(0.25)
    raise AssertionError(f"not within {timeout_s} s: {last}")


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["one disk", "one disk read-only", "buffer elsewhere"])
def test_a_failing_disk_is_reported_and_loses_nothing(tmp_path: Path, layout: str) -> None:
    disks = (
        readonly_disk(tmp_path / "disk", tmp_path)
        if layout.endswith("read-only")
        else small_disk(tmp_path / "disk", size_mb=24)
    )
    with disks as disk:
        buffer_dir = disk.path if layout.startswith("one disk") else tmp_path
        with drill(tmp_path, db_dir=disk.path, buffer_dir=buffer_dir) as d:
            _poll(d, lambda r, code, s: code == 200 and s["samples_stored"] > 20, 60)
            fresh_s = d.freshness_bound_s()  # what this machine manages before the fault
            disk.fault()
            took, seen = _poll(d, lambda r, code, s: code == 503 and not r["storage"], 10)
            assert took <= 5.0, seen
            assert any(p.startswith("storage:") for p in seen["readyz"]["problems"]), seen
            if layout.startswith("one disk"):
                took, seen = _poll(
                    d, lambda r, c, s: s["buffer"] == "down" and s["samples_in_memory"] > 0, 10
                )
                assert any(p.startswith("buffer:") for p in seen["readyz"]["problems"]), seen
            else:
                _poll(d, lambda r, c, s: s["samples_in_buffer"] > 0, 10)
            time.sleep(6.0)  # the fault lasts a while: samples keep arriving
            disk.recover()
            took, seen = _poll(
                d,
                lambda r, c, s: (
                    s["database"] == "up"
                    and s["samples_in_memory"] == 0
                    and s["samples_in_buffer"] == 0
                ),
                20,
            )
            assert took <= 10.0, seen
            assert seen["storage"]["samples_dropped"] == 0, seen
            _poll(d, lambda r, code, s: code == 200, 10)
            time.sleep(2.0)
            for protocol in LOOPS:
                a = d.account(protocol)
                assert a.silent_holes == 0 and a.lost == 0, (protocol, a)
                assert a.newest_us and time.time() - a.newest_us / 1e6 < fresh_s, (protocol, a)
        log = d.log.read_text(errors="replace")
        assert "Traceback" not in log, log[-3000:]
        assert log.count("store not taking samples") == 1, log[-3000:]
