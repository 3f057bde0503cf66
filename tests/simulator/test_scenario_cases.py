"""Scenario files, Telegraf style: each folder of tests/scenario_cases holds a scenario.toml and
the error it must be refused with (empty file: the scenario is valid)."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import case_folders, check_refusal

from plantcheck.simulator.scenario import load_scenario

CASES = case_folders("scenario_cases")


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_scenario_case(case: Path) -> None:
    expected = (case / "expected_error.txt").read_text().strip()
    check_refusal(case / "scenario.toml", expected, lambda p: load_scenario(p).loop)


def test_default_scenario_has_the_demo_loops() -> None:
    sc = load_scenario()
    causes = {spec.cause for spec in sc.loop}
    assert len(sc.loop) >= 8
    assert {"ok", "stiction", "aggressive_tuning", "sluggish_tuning"} <= causes
    assert {"external_disturbance", "saturation", "positioner_fault"} <= causes
    assert any(s.expose_mv and s.positioner for s in sc.loop)
    assert sum(s.type == "level" and s.cause == "stiction" for s in sc.loop) == 1
    # a sticky valve whose cycle reaches two loops downstream (issue 49 item 3)
    carried = [s.id for s in sc.loop for d in s.disturbances if d.from_loop == "FIC801"]
    assert sorted(carried) == ["PIC803", "TIC802"]
