"""The reliability rules of the Hammerstein estimate (``diagnosis/quantification_rules.py``):
a clean stick-slip fit passes every rule, and each rule refuses, with its own code, the one
flaw it is there for."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from plantcheck.diagnosis.quantification import QuantificationParams
from plantcheck.diagnosis.quantification_rules import RULES, Evidence, refusals


def _stick_slip_valve(n: int = 1000, period: int = 100, jump: float = 3.0) -> np.ndarray:
    """A valve stuck between slips of ``jump``, one per half-period."""
    k = np.arange(n)
    return np.where((k // (period // 2)) % 2 == 0, 0.0, jump)


def _clean() -> Evidence:
    """A window of 10 cycles whose Kano fit is sharp in S, beats a linear valve and the He
    model, keeps the valve stuck between one slip per half-cycle, S most of the OP travel."""
    S = np.linspace(1.0, 6.0, 51)
    score = 1.0 + 2.0 * np.abs(S - 3.0)  # sharp minimum at S* = 3
    return Evidence(
        params=QuantificationParams(),
        integrating=False,
        cycles=10.0,
        period_samples=100.0,
        n_samples=1000,
        model="kano",
        best=1.0,
        fit=85.0,
        s_best=3.0,
        j_best=3.0,
        S=S,
        score=score,
        other_model="he",
        other_best=2.0,
        other_s_best=3.5,
        score_ratio=0.3,
        grid_top=6.0,
        tradeoff_S=np.array([2.4, 3.6]),
        tradeoff_score=np.array([1.5, 1.6]),
        valve=_stick_slip_valve(),
        excursion=3.5,
    )


def test_a_clean_fit_passes_every_rule() -> None:
    assert refusals(_clean()) == []


FLAWS: list[tuple[dict[str, object], str]] = [
    ({"cycles": 4.0}, "few_cycles"),
    ({"best": float("inf"), "other_best": float("inf")}, "no_model"),
    ({"fit": 40.0}, "poor_fit"),
    ({"score_ratio": 0.9}, "like_linear"),
    ({"s_best": 6.0, "S": np.linspace(1.0, 6.0, 51)}, "grid_edge"),
    ({"score": np.ones(51)}, "wide_region"),
    ({"tradeoff_score": np.array([1.0, 1.6])}, "delay_tradeoff"),
    ({"other_best": 1.1, "other_s_best": 4.5}, "models_disagree"),
    ({"valve": np.cumsum(np.full(1000, 0.01))}, "rarely_stuck"),
    ({"valve": _stick_slip_valve(period=10)}, "many_slips"),
    ({"excursion": 10.0}, "small_share"),
    ({"j_best": 0.1}, "deadband_only"),
]
"""One flaw per rule (rule 4c, far_rival, has its own test) and the code that refuses it."""


@pytest.mark.parametrize(("change", "code"), FLAWS)
def test_each_rule_refuses_its_flaw(change: dict[str, object], code: str) -> None:
    codes = [r.code for r in refusals(replace(_clean(), **change))]  # type: ignore[arg-type]
    assert code in codes, codes


def test_a_far_rival_that_fits_as_well_refuses_the_estimate() -> None:
    ev = _clean()
    score = ev.score.copy()
    score[0] = 1.1  # S = 1 fits within 10 % of S* = 3
    assert [r.code for r in refusals(replace(ev, score=score))] == ["far_rival"]


def test_every_rule_has_its_own_code() -> None:
    codes = {code for _, code in FLAWS} | {"far_rival"}
    assert len(codes) == len(RULES)
