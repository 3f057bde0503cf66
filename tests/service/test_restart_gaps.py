"""A crashed collector leaves no unmarked gap (issue 27): ``plantcheck ingest`` killed with
SIGKILL and started again stores a gap marker right after each tag's last sample, so the
windows never hold a value across the dead time. Real processes: the simulator and the
collector, a real SQLite file (``tests/crash_drill.py``). What a crash loses, in seconds, is
timed by ``benchmarks/crash_loss.py``, not asserted here."""

from __future__ import annotations

from pathlib import Path

import pytest
from crash_drill import crash_drill

from plantcheck.core.status_codes import BAD_NO_COMMUNICATION


@pytest.mark.slow
def test_collector_killed_and_restarted_marks_the_dead_time(tmp_path: Path) -> None:
    d = crash_drill(tmp_path, dead_s=3.0)
    assert len(d.killed) >= 10
    assert d.killed[-1][2] != BAD_NO_COMMUNICATION  # a crash writes nothing on its way out
    last = d.killed[-1][0]
    marker = [r for r in d.rows if r[0] == last + 1]
    assert marker and marker[0][2] == BAD_NO_COMMUNICATION and marker[0][1] is None, d.rows[-12:]
    resumed = [r for r in d.rows if r[0] > last + 1 and r[2] != BAD_NO_COMMUNICATION]
    assert resumed and resumed[0][0] - last > 2_000_000  # the dead time lies inside the gap
