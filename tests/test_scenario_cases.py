"""Scenario files, Telegraf style: each folder of tests/scenario_cases holds a scenario.toml and
the error it must be refused with (empty file: the scenario is valid)."""

from __future__ import annotations

from pathlib import Path

import pytest

from plantcheck.service.toml_config import ConfigError
from plantcheck.simulator.scenario import load_scenario

CASES = sorted(p for p in (Path(__file__).parent / "scenario_cases").iterdir() if p.is_dir())


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_scenario_case(case: Path) -> None:
    expected = (case / "expected_error.txt").read_text().strip()
    path = case / "scenario.toml"
    if not expected:
        assert load_scenario(path).loop
        return
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert expected in message, message
    assert "\n" not in message


def test_default_scenario_has_the_eight_demo_loops() -> None:
    sc = load_scenario()
    causes = {spec.cause for spec in sc.loop}
    assert len(sc.loop) >= 8
    assert {"ok", "stiction", "aggressive_tuning", "sluggish_tuning"} <= causes
    assert {"external_disturbance", "saturation", "positioner_fault"} <= causes
    assert any(s.expose_mv and s.positioner for s in sc.loop)
    assert sum(s.type == "level" and s.cause == "stiction" for s in sc.loop) == 1
