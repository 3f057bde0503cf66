"""How soon a failing disk is reported and how soon writing resumes once it recovers (issue 45).

The drill of ``tests/service/test_disk_faults.py``, timed and repeated: ``plantcheck simulate``
serves Modbus TCP and OPC UA, ``plantcheck run`` collects one loop from each into SQLite on a
small real filesystem (``tests/smalldisk.py``: a tmpfs that fills, or a FUSE pass-through
turned read-only; both need root). For each fault, ``--repeat`` times: the disk fails, the
time until ``/readyz`` answers 503 naming storage; the fault lasts ``--hold`` s; the disk
recovers, the time until the database is up and nothing waits in memory or in the buffer
(``/readyz`` and ``GET /api/v1/storage`` polled every 0.25 s). Prints each cycle and the min /
median / max per fault. The README promises 503 within 5 s and writing back within 5 s of the
recovery (commits are retried at most 5 s apart); the test only waits for both within
``TIMEOUT_S`` and prints the times, so that a loaded machine cannot fail it on a clock.

    python benchmarks/disk_faults.py [--repeat 3] [--hold 6] [--cpu-load 0]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from cpu_load import busy_processes
from smalldisk import fuse_reason, mount_reason, readonly_disk, small_disk
from soak import Drill, drill

LAYOUTS = ("one disk", "one disk read-only", "buffer elsewhere")
"""The three faults: the database and the buffer on the one disk that fills (samples wait in
memory), the same disk turned read-only, the database's disk full with the buffer on another
(the buffer takes them)."""
TIMEOUT_S = 60.0
"""How long a cycle waits for each answer before it calls the service stuck, s: twelve times
the README's 5 s, for a loaded machine."""

Bodies = dict[str, Any]
"""``/readyz``'s body and status and ``GET /api/v1/storage``'s body at one poll."""


class Disk(Protocol):
    """``smalldisk``'s disks: where they are mounted, and the fault turned on and off."""

    path: Path

    def fault(self) -> None: ...

    def recover(self) -> None: ...


@dataclass(frozen=True)
class FaultCycle:
    """One fault, timed: seconds from the fault to the report and from the recovery to the
    samples written back, with what the service answered at each step."""

    reported_s: float
    written_back_s: float
    reported: Bodies
    """The first answer with ``/readyz`` 503 and storage down."""
    held: Bodies
    """The first answer with the samples held (in memory, or in the buffer)."""
    written_back: Bodies
    """The first answer with the database up and nothing held."""


def poll_storage(
    d: Drill, until: Callable[[Bodies], bool], timeout_s: float = TIMEOUT_S
) -> tuple[float, Bodies]:
    """Seconds until ``until(bodies)`` held (polled every 0.25 s), and those bodies; an
    AssertionError with the last answer after ``timeout_s``."""
    t0 = time.monotonic()
    last: Bodies = {}
    while time.monotonic() - t0 < timeout_s:
        try:
            r = httpx.get(f"{d.api_url}/readyz", timeout=2)
            s = httpx.get(f"{d.api_url}/api/v1/storage", timeout=2).json()
            last = {"readyz": r.json(), "status": r.status_code, "storage": s}
            if until(last):
                return time.monotonic() - t0, last
        except httpx.HTTPError as exc:
            last = {"error": repr(exc)}
        time.sleep(0.25)
    raise AssertionError(f"not within {timeout_s:g} s: {last}")


def fault_cycle(d: Drill, disk: Disk, in_memory: bool, hold_s: float = 6.0) -> FaultCycle:
    """Fail ``disk``, wait for the report and for the samples held (in memory when
    ``in_memory``, else in the buffer), keep the fault ``hold_s`` s while samples arrive,
    recover it and wait until every held sample is written."""
    disk.fault()
    reported_s, reported = poll_storage(
        d, lambda b: b["status"] == 503 and not b["readyz"]["storage"]
    )
    if in_memory:
        _, held = poll_storage(
            d,
            lambda b: b["storage"]["buffer"] == "down" and b["storage"]["samples_in_memory"] > 0,
        )
    else:
        _, held = poll_storage(d, lambda b: b["storage"]["samples_in_buffer"] > 0)
    time.sleep(hold_s)
    disk.recover()
    written_back_s, written_back = poll_storage(
        d,
        lambda b: (
            b["storage"]["database"] == "up"
            and b["storage"]["samples_in_memory"] == 0
            and b["storage"]["samples_in_buffer"] == 0
        ),
    )
    return FaultCycle(reported_s, written_back_s, reported, held, written_back)


def layout_disk(layout: str, tmp: Path) -> AbstractContextManager[Disk]:
    """The disk ``layout`` fails: a FUSE pass-through for the read-only fault, else a tmpfs."""
    if layout.endswith("read-only"):
        return readonly_disk(tmp / "disk", tmp)
    return small_disk(tmp / "disk", size_mb=24)


@contextmanager
def drill_on(layout: str, tmp: Path) -> Iterator[tuple[Drill, Disk]]:
    """The drill with its database (and, for "one disk", its buffer) on ``layout``'s disk,
    collecting (at least 20 samples stored) when it is handed over."""
    with layout_disk(layout, tmp) as disk:
        buffer_dir = disk.path if layout.startswith("one disk") else tmp
        with drill(tmp, db_dir=disk.path, buffer_dir=buffer_dir) as d:
            poll_storage(d, lambda b: b["status"] == 200 and b["storage"]["samples_stored"] > 20)
            yield d, disk


def _summary(xs: list[float]) -> str:
    return f"min {min(xs):5.2f}  median {statistics.median(xs):5.2f}  max {max(xs):5.2f} s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="cycles per fault (default 3)")
    ap.add_argument("--hold", type=float, default=6.0, help="seconds each fault lasts")
    ap.add_argument("--cpu-load", type=int, default=0, help="busy processes beside the drill")
    ap.add_argument("--layouts", nargs="+", choices=LAYOUTS, default=list(LAYOUTS))
    args = ap.parse_args()
    reason = mount_reason() or (
        fuse_reason() if any(x.endswith("read-only") for x in args.layouts) else ""
    )
    if reason:
        raise SystemExit(f"cannot run here: {reason}")
    times: dict[str, tuple[list[float], list[float]]] = {x: ([], []) for x in args.layouts}
    with busy_processes(args.cpu_load):
        for layout in args.layouts:
            with (
                tempfile.TemporaryDirectory(prefix="plantcheck-disk-") as tmp,
                drill_on(layout, Path(tmp)) as (d, disk),
            ):
                for k in range(args.repeat):
                    c = fault_cycle(d, disk, layout.startswith("one disk"), args.hold)
                    times[layout][0].append(c.reported_s)
                    times[layout][1].append(c.written_back_s)
                    print(
                        f"{layout:18s} cycle {k + 1}: 503 after {c.reported_s:5.2f} s, written "
                        f"back {c.written_back_s:5.2f} s after the recovery",
                        flush=True,
                    )
    print(f"\n{args.repeat} cycles per fault, {args.hold:g}-s faults, {args.cpu_load} busy:")
    for layout, (reported, back) in times.items():
        print(f"{layout:18s} 503: {_summary(reported)};  written back: {_summary(back)}")


if __name__ == "__main__":
    main()
