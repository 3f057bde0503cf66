"""Start-up of the command line (issue 29): wall time and peak memory of ``plantcheck
--version``, ``--help`` and ``diagnose`` of a 3,600-sample record, each a new process as a
user runs it (median of ``--repeat`` runs). Targets: 0.2 s for --version and --help, 0.7 s for
the diagnosis.

    python benchmarks/cli_startup.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from machine_speed import machine_line

CLI = [sys.executable, "-m", "plantcheck.service.cli"]


def _record(path: Path, n: int = 3600) -> None:
    """A sticky-looking loop: PV and OP with noise and a slow cycle, 1 s samples."""
    rng = np.random.default_rng(1)
    k = np.arange(n)
    pv = 50 + np.sign(np.sin(2 * np.pi * k / 120)) + 0.1 * rng.normal(size=n)
    op = 40 + 3 * np.sin(2 * np.pi * k / 120 - 1) + 0.2 * rng.normal(size=n)
    rows = "".join(f"{t},50,{a:.3f},{b:.3f}\n" for t, a, b in zip(k, pv, op, strict=True))
    path.write_text("t,sp,pv,op\n" + rows, encoding="utf-8")


def _time(args: list[str], repeat: int) -> tuple[float, float]:
    """Median wall time (s) and the largest peak RSS (MB) of ``repeat`` runs."""
    walls = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([*CLI, *args], capture_output=True, check=True)
        walls.append(time.perf_counter() - t0)
    peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return statistics.median(walls), peak_kb / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "loop.csv"
        _record(rec)
        print(machine_line())
        print("command                        median wall   peak RSS so far")
        for label, argv in (
            ("plantcheck --version", ["--version"]),
            ("plantcheck --help", ["--help"]),
            ("plantcheck diagnose (3,600)", ["diagnose", str(rec), "--json"]),
        ):
            wall, mb = _time(argv, args.repeat)
            print(f"{label:30s} {wall:8.2f} s   {mb:8.0f} MB")


if __name__ == "__main__":
    main()
