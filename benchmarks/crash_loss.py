"""What a crashed collector loses (the README's loss bound on a crash), printed as figures.

    python benchmarks/crash_loss.py [--repeat 5] [--cpu-load 0]

The drill of ``tests/service/test_restart_gaps.py`` (``tests/crash_drill.py``), repeated:
``plantcheck ingest`` polls one Modbus loop every 0.5 s and commits every 0.2 s
(``crash_drill.POLL_INTERVAL_S``, ``COMMIT_INTERVAL_S``), is killed
with SIGKILL once 10 samples are stored, and the time from the newest stored sample to the
kill is what the crash lost. The README bounds it by the commit interval plus the poll under
way plus the commit's own time (0.7 s and a little here); ``--cpu-load N`` runs ``N`` busy
processes beside it, as a loaded CI machine would.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from cpu_load import busy_processes
from crash_drill import COMMIT_INTERVAL_S, POLL_INTERVAL_S, crash_drill


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5, help="drills (default 5)")
    ap.add_argument("--cpu-load", type=int, default=0, help="busy processes beside the drill")
    args = ap.parse_args()
    if args.repeat < 1:
        raise SystemExit("--repeat: give 1 or more drills")
    lost: list[float] = []
    with busy_processes(args.cpu_load):
        for k in range(args.repeat):
            with tempfile.TemporaryDirectory(prefix="plantcheck-crash-") as tmp:
                d = crash_drill(Path(tmp), dead_s=1.0)
            lost.append(d.lost_s)
            print(f"drill {k + 1}: {d.lost_s:.2f} s lost ({len(d.killed)} samples stored)")
    print(
        f"lost on a crash (commits every {COMMIT_INTERVAL_S:g} s, polls every "
        f"{POLL_INTERVAL_S:g} s, {args.cpu_load} busy): "
        f"min {min(lost):.2f} s, median {statistics.median(lost):.2f} s, max {max(lost):.2f} s"
    )


if __name__ == "__main__":
    main()
