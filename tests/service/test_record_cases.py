"""Record-file cases, one folder each (as Telegraf's modbus plugin tests its configs).

Each folder under ``record_cases/`` holds ``record.csv`` (absent for the missing-file case) and
``expected.json``: the exit status, and either a fragment of the one-line error on stderr or the
diagnosed cause and a fragment of a note. Never a traceback, and after a diagnosis nothing on
stderr (no library warning).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers import RunCli

CASES = sorted(p for p in (Path(__file__).parents[1] / "record_cases").iterdir() if p.is_dir())


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_record_case(case: Path, run_cli: RunCli) -> None:
    expected = json.loads((case / "expected.json").read_text())
    args = ["diagnose", str(case / "record.csv"), "--json", *expected.get("args", [])]
    proc = run_cli(*args)
    assert "Traceback" not in proc.stderr
    assert proc.returncode == expected["exit"], proc.stderr
    if expected["exit"] == 2:
        lines = proc.stderr.strip().splitlines()
        assert len(lines) >= 1
        assert expected["stderr"].lower() in proc.stderr.lower()
        assert proc.stdout == ""
        return
    assert proc.stderr == "", proc.stderr
    out = json.loads(proc.stdout)
    assert out["schema"] == "plantcheck.diagnosis/1"
    if "cause" in expected:
        assert out["cause"] == expected["cause"], out["notes"]
    if "chain" in expected:
        assert out["chain"] == expected["chain"]
        assert out["valve"]["state"] == expected["valve_state"]
        assert "bias" in out["valve"]["kpis"]
    else:
        assert out["chain"] == "standard" and out["valve"] is None
    if "note" in expected:
        assert any(expected["note"].lower() in n.lower() for n in out["notes"]), out["notes"]
