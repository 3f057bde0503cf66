"""Labelled closed loops generated here (simulator.cases): every cause on its own cases.

Self-regulating (flow, pressure, two temperature) and integrating (level) processes with dead
time, SIMC PI control, Kano or He sticky valves (S 1–8 %, J/S 0.2–1), sinusoidal and random
load disturbances, gain at 0.8–0.95 of the ultimate gain, sluggish tuning (Kc × 0.2, Ti × 5),
noise σ 0.05–0.5 %, sample times 0.2–3 s, lengths 1,000–20,000. The confusion matrix is printed;
the bars below are the floors the chain must keep (the measured figures are higher and are
reported by benchmarks/diagnosis_accuracy.py).
"""

from __future__ import annotations

import collections

import pytest
from helpers import ComputedOnce

from plantcheck.diagnosis import diagnose
from plantcheck.simulator.cases import generate_cases
from plantcheck.simulator.loop import simulate_loop

MIN_RECALL = {
    "ok": 0.9,
    "stiction": 0.5,
    "aggressive_tuning": 0.65,
    "sluggish_tuning": 0.4,
    "external_disturbance": 0.75,
}


def _confusion() -> list[tuple[str, str, int]]:
    """(true cause, diagnosed cause, windows) over the generated cases; prints the matrix."""
    conf: collections.Counter[tuple[str, str]] = collections.Counter()
    for c in generate_cases(seed=11, lengths=(1000, 5000, 20000)):
        r = simulate_loop(c.config)
        d = diagnose(
            r.pv, r.op, c.config.sample_time_s, sp=r.sp, loop_type=c.loop_type, quantify=False
        )
        conf[(c.cause, d.cause)] += 1
    causes = sorted({a for a, _ in conf} | {b for _, b in conf})
    print("\ntrue \\ predicted".ljust(24) + "".join(x[:11].rjust(12) for x in causes))
    for a in sorted({a for a, _ in conf}):
        print(a.ljust(23) + "".join(str(conf[(a, b)]).rjust(12) for b in causes))
    return [(a, b, n) for (a, b), n in conf.items()]


@pytest.fixture(scope="module")
def confusion(computed_once: ComputedOnce) -> collections.Counter[tuple[str, str]]:
    return collections.Counter(
        {(a, b): n for a, b, n in computed_once("generated-cases-confusion", _confusion)}
    )


@pytest.mark.parametrize("cause", sorted(MIN_RECALL))
def test_cause_recognised_on_its_cases(
    cause: str, confusion: collections.Counter[tuple[str, str]]
) -> None:
    total = sum(v for (a, _), v in confusion.items() if a == cause)
    assert total > 0
    recall = confusion[(cause, cause)] / total
    assert recall >= MIN_RECALL[cause], f"{cause}: recall {recall:.2f}"


def test_healthy_loops_rarely_called_stiction(
    confusion: collections.Counter[tuple[str, str]],
) -> None:
    total = sum(v for (a, _), v in confusion.items() if a == "ok")
    assert confusion[("ok", "stiction")] <= 0.02 * total
