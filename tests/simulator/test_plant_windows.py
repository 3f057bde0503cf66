"""simulator/plant_windows.py: the plant windows on the benchmark's process table and on the
tables the chain was not developed on (``cases.OTHER_PROCESS_SETS``)."""

from __future__ import annotations

import pytest

from plantcheck.simulator.cases import OTHER_PROCESS_SETS, PROCESSES
from plantcheck.simulator.plant_windows import CLASSES, generate_plant_window_cases


def test_the_benchmark_table_is_the_default() -> None:
    default = [pc.case.name for pc in generate_plant_window_cases(1, 1)]
    explicit = [pc.case.name for pc in generate_plant_window_cases(1, 1, PROCESSES)]
    assert default == explicit


@pytest.mark.parametrize("table", sorted(OTHER_PROCESS_SETS))
def test_another_table_gives_every_class_on_its_own_processes(table: str) -> None:
    processes = OTHER_PROCESS_SETS[table]
    cases = [pc.case for pc in generate_plant_window_cases(1, 1, processes)]
    assert len(cases) == len(processes) * 3 * len(CLASSES)
    assert {c.cause for c in cases} == set(CLASSES)
    used = {c.config.process for c in cases}
    assert used == {proc for _, proc in processes.values()}
    assert {c.loop_type for c in cases} == {lt for lt, _ in processes.values()}
