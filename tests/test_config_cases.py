"""Configuration files, Telegraf style: each folder of tests/config_cases holds a
plantcheck.toml and the one-line error it must be refused with (empty file: it is valid)."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import case_folders, check_refusal

from plantcheck.service.config import load_config

CASES = case_folders("config_cases")


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_config_case(case: Path) -> None:
    expected = (case / "expected_error.txt").read_text().strip()
    check_refusal(case / "plantcheck.toml", expected, load_config)
