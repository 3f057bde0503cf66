"""Configuration files, Telegraf style: each folder of tests/config_cases holds a
plantcheck.toml and the one-line error it must be refused with (empty file: it is valid).

A folder with a ``command.txt`` holds a file that loads but cannot be used (a buffer path
nobody can write, a database nobody serves): that command (``run``) must refuse it at start
with exit 2 and the one-line error, never a traceback."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import RunCli, case_folders, check_refusal

from plantcheck.service.config import load_config

CASES = case_folders("config_cases")


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_config_case(case: Path, run_cli: RunCli) -> None:
    expected = (case / "expected_error.txt").read_text().strip()
    command = case / "command.txt"
    if not command.exists():
        check_refusal(case / "plantcheck.toml", expected, load_config)
        return
    load_config(case / "plantcheck.toml")  # valid as a file: refused only when used
    r = run_cli(*command.read_text().split(), "--config", str(case / "plantcheck.toml"))
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    errors = [line for line in r.stderr.splitlines() if line.startswith("plantcheck: error:")]
    assert len(errors) == 1 and expected in errors[0], r.stderr
