"""Configuration files, Telegraf style: each folder of tests/config_cases holds a
plantcheck.toml and the one-line error it must be refused with (empty file: it is valid)."""

from __future__ import annotations

from pathlib import Path

import pytest

from plantcheck.service.config import load_config
from plantcheck.service.toml_config import ConfigError

CASES = sorted(p for p in (Path(__file__).parent / "config_cases").iterdir() if p.is_dir())


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_config_case(case: Path) -> None:
    expected = (case / "expected_error.txt").read_text().strip()
    path = case / "plantcheck.toml"
    if not expected:
        load_config(path)
        return
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert expected in message, message
    assert "\n" not in message
