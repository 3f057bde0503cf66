"""The loop priority (issue 49 item 2): state and distance from healthy, weighed by criticality,
checked against hand-computed values and the orderings a plant engineer expects."""

from __future__ import annotations

import pytest

from plantcheck.diagnosis.priority import kpi_distance, loop_priority


def test_priority_by_hand() -> None:
    # fault, criticality 5, healthy indices: 100 · 1 · 0.7
    assert loop_priority("fault", 5, {}) == 70.0
    # warning, default criticality 3: 100 · 0.6 · 0.7 · 0.6 = 25.2
    assert loop_priority("warning") == 25.2
    # ok, criticality 4, variability 3× its baseline: distance (3 − 1) / 4 = 0.5 → 100·0.8·0.15
    assert loop_priority("ok", 4, {"variability_ratio": 3.0}) == 12.0
    # the largest shortfall counts: Harris 0.1 → (0.5 − 0.1) / 0.5 = 0.8; in auto 90 % → 0.1
    k = {"harris_index": 0.1, "service_factor": 0.9, "op_limit": {"value": 80.0, "share": 0.3}}
    assert kpi_distance(k) == pytest.approx(0.8)
    assert loop_priority("fault", 5, {"variability_ratio": 9.0}) == 100.0
    assert loop_priority("ok", 1, {}) == 0.0


def test_the_worst_loops_come_first() -> None:
    ranked = sorted(
        [
            ("healthy", loop_priority("ok", 5, {"variability_ratio": 1.0, "harris_index": 0.8})),
            ("drifting", loop_priority("ok", 3, {"variability_ratio": 5.0})),
            ("warning minor", loop_priority("warning", 1, {})),
            ("warning critical", loop_priority("warning", 5, {})),
            ("fault", loop_priority("fault", 3, {"service_factor": 0.2})),
        ],
        key=lambda x: -x[1],
    )
    assert [n for n, _ in ranked] == [
        "fault",
        "warning critical",
        "drifting",
        "warning minor",
        "healthy",
    ]
    # criticality outside 1-5 is held to it; None indices are unknown, not bad
    assert loop_priority("fault", 9) == loop_priority("fault", 5)
    assert kpi_distance({"harris_index": None, "variability_ratio": None}) == 0.0
