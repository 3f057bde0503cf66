"""Memory and CPU of a process and every process below it (Linux /proc), for the benchmarks
that run the service as real processes (soak.py, scale.py)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

TICK = os.sysconf("SC_CLK_TCK")


def tree(pid: int) -> Iterator[int]:
    """``pid`` and its live descendants (those gone meanwhile are skipped)."""
    todo = [pid]
    while todo:
        p = todo.pop()
        yield p
        try:
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(k) for k in (task / "children").read_text().split()]
        except OSError:
            continue


def rss_kb(pid: int) -> int:
    """Resident memory of the tree, kB."""
    total = 0
    for p in tree(pid):
        try:
            status = Path(f"/proc/{p}/status").read_text()
        except OSError:
            continue
        total += int(status.split("VmRSS:")[1].split()[0]) if "VmRSS:" in status else 0
    return total


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of the tree, with the children each process has waited for."""
    total = 0.0
    for p in tree(pid):
        try:
            f = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(f[11]) + int(f[12]) + int(f[13]) + int(f[14])) / TICK
    return total
