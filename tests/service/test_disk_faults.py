"""Disk faults with real processes (issue 45): ``plantcheck simulate`` serves Modbus TCP and
OPC UA, ``plantcheck run`` collects one loop from each into SQLite on a small real filesystem
(``smalldisk``: a tmpfs, which needs root; skipped with that reason without it), and the test
fills that filesystem, then frees it; or on a FUSE pass-through (``readonlyfs``) that the test
turns read-only, then writable again.

Three faults: the database and the durable buffer on the one disk that fills (samples wait in
memory), the same disk turned read-only, and the database's disk full with the buffer on
another (the buffer takes them). For each: ``/readyz`` answers 503 naming storage,
``GET /api/v1/storage`` says where the samples are, writing resumes once the disk recovers,
and the stored history of both protocols has no hole that a gap marker does not cover. How
soon the fault is reported and the samples written back is printed here and measured by
``benchmarks/disk_faults.py`` (the README's 5 s): the test waits up to a minute for each, so
that a loaded machine cannot fail it on a clock.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from disk_faults import LAYOUTS, drill_on, fault_cycle, poll_storage
from soak import LOOPS


@pytest.mark.slow
@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_failing_disk_is_reported_and_loses_nothing(tmp_path: Path, layout: str) -> None:
    with drill_on(layout, tmp_path) as (d, disk):
        fresh_s = d.freshness_bound_s()  # what this machine manages before the fault
        c = fault_cycle(d, disk, in_memory=layout.startswith("one disk"))
        print(f"{layout}: 503 after {c.reported_s:.2f} s, written back {c.written_back_s:.2f} s")
        assert any(p.startswith("storage:") for p in c.reported["readyz"]["problems"]), c
        if layout.startswith("one disk"):
            assert any(p.startswith("buffer:") for p in c.held["readyz"]["problems"]), c
        assert c.written_back["storage"]["samples_dropped"] == 0, c
        poll_storage(d, lambda b: b["status"] == 200)
        time.sleep(2.0)
        for protocol in LOOPS:
            a = d.account(protocol)
            assert a.silent_holes == 0 and a.lost == 0, (protocol, a)
            assert a.newest_us and time.time() - a.newest_us / 1e6 < fresh_s, (protocol, a)
    log = d.log.read_text(errors="replace")  # the service stopped: its whole log
    assert "Traceback" not in log, log[-3000:]
    assert log.count("store not taking samples") == 1, log[-3000:]
