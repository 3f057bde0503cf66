"""Stiction Analysis Module (SAM): applicable tests per loop type and their vote.

Applicability follows methods.md §3.4 and the thesis' Table 2.2 (Bacci di Capaci 2016):
Horch's CCF and the area ratio do not apply to integrating (level) loops, which get Horch's
histogram test instead; the curve-fitting test reads OP for self-regulating loops and PV for
integrating ones. Vote [R]: stiction if #stiction >= 2 and #stiction > #no_stiction;
no stiction if #no_stiction >= 2 and #no_stiction > #stiction; a tie of at least two each is
broken by the waveform-shape tests (relay, curve fit, area ratio, histogram), since Horch's CCF
mostly reads the controller's phase at the oscillation frequency and bicoherence flags any
nonlinearity; otherwise undecided.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

from plantcheck.core.vocabulary import LOOP_TYPES, LoopType
from plantcheck.diagnosis.stiction_verdict import StictionTestResult

__all__ = ["LOOP_TYPES"]  # re-exported: the chain checks its loop_type against them

INTEGRATING_TYPES = frozenset({LoopType.level.value})

SHAPE_TESTS = frozenset({"relay", "curve_fit", "area_ratio", "histogram"})
"""Tests that read the waveform itself; they break ties in the vote."""
CONFIRMING_TESTS = frozenset({"relay", "area_ratio", "histogram", "stick_slip"})
"""Tests whose ``stiction`` vote confirms a nonlinearity test's (the curve fit passes a
lightly damped linear cycle too, so it does not confirm)."""

APPLICABLE_TESTS: dict[str, tuple[str, ...]] = {
    "self_regulating": ("relay", "curve_fit", "cross_correlation", "bicoherence", "area_ratio"),
    "integrating": ("relay", "curve_fit", "histogram", "bicoherence"),
}


def is_integrating(loop_type: str) -> bool:
    """True for loop types whose process integrates (level)."""
    return loop_type in INTEGRATING_TYPES


def applicable_tests(loop_type: str) -> tuple[str, ...]:
    """Names of the stiction tests that apply to ``loop_type``."""
    key = "integrating" if is_integrating(loop_type) else "self_regulating"
    return APPLICABLE_TESTS[key]


@dataclass(frozen=True)
class VoteResult:
    """Outcome of the vote: decision, the counts, and a score in [−1, 1] (+1 all stiction)."""

    decision: Literal["stiction", "no_stiction", "undecided"]
    n_stiction: int
    n_no_stiction: int
    n_tests: int
    score: float


@dataclass(frozen=True)
class VoteParams:
    """Vote rule parameters [R]."""

    min_votes: int = 2
    """Fewest concordant votes for a decision."""
    shape_confirmed: frozenset[str] = frozenset({"bicoherence"})
    """Tests whose ``stiction`` vote counts only when a waveform-shape test or the stick-slip
    events agree [R]: bicoherence flags any nonlinearity, which a lightly damped cycle with
    noise shows too; Choudhury et al. (2004) confirm it with the PV(OP) shape."""
    curve_fit_confirmed: frozenset[str] = frozenset({"histogram"})
    """Tests whose ``stiction`` vote counts only when the curve fit says stiction too [R]:
    Horch's second-difference histogram is peaked for a level loop ringing in bursts after
    set-point moves or clamps as for a sticky one; only the PV's triangular shape (He et al.
    2007, ``ShapeParams.curvefit_yes_integrating``) tells them apart. Generated windows: seven
    aggressive level loops (seeds 1-4, three process tables) no longer read stiction, no sticky
    one lost; refinery: the one non-sticky level window that read stiction (2111LIC31102B)
    does not."""
    curve_fit_alone: float = 0.73
    """A curve-fit index (He et al. 2007) at or above this decides ``stiction`` alone, where
    no waveform-shape test says no stiction and the cycle is sustained (the chain checks the
    ACF decay ratio; ``curve_fit_decides``). He et al. call 0.6 stiction; a lightly damped
    linear cycle passes 0.6 too, so alone the index needs a triangle that fits with at most
    0.37 × the sine's error. Generated plant windows, seeds 1-4 on the three process tables
    (2,592 windows): aggressive loops read up to 0.71 (at 0.70 three read stiction), one
    disturbance at 1.2 × the ultimate period 0.726 (it reads stiction at 0.72); sticky valves
    that read as aggressive tuning or a disturbance 0.6-0.93, 28 of them found at 0.73, about
    a quarter fewer at 0.75. Real records: no non-sticky loop above 0.69 (a refinery level
    window that reads ok), ISDB's no-stiction loop 0.41 [R]."""


def curve_fit_decides(
    results: list[StictionTestResult], sustained: bool, params: VoteParams | None = None
) -> StictionTestResult | None:
    """The curve-fit result that decides ``stiction`` alone (``VoteParams.curve_fit_alone``),
    or None. ``sustained``: the cycle does not die out within a cycle (a sticky valve's limit
    cycle sustains itself; Miao & Seborg's decay ratio at least 0.5)."""
    p = params or VoteParams()
    if not sustained:
        return None
    if any(r.verdict == "no_stiction" and r.name in SHAPE_TESTS for r in results):
        return None
    for r in results:
        if r.name == "curve_fit" and r.value is not None and r.value >= p.curve_fit_alone:
            return r
    return None


def _unconfirmed(
    results: list[StictionTestResult], names: frozenset[str]
) -> list[StictionTestResult]:
    """``results`` with the ``stiction`` votes of the tests ``names`` made ``undecided``: no
    test that they need agreed."""
    return [
        replace(r, verdict="undecided") if r.verdict == "stiction" and r.name in names else r
        for r in results
    ]


def vote(results: list[StictionTestResult], params: VoteParams | None = None) -> VoteResult:
    """Combine applicable test verdicts (methods.md §3.4)."""
    p = params or VoteParams()
    used = [r for r in results if r.verdict != "not_applicable"]
    if not any(r.name == "curve_fit" and r.verdict == "stiction" for r in used):
        used = _unconfirmed(used, p.curve_fit_confirmed)
    if not any(r.verdict == "stiction" and r.name in CONFIRMING_TESTS for r in used):
        used = _unconfirmed(used, p.shape_confirmed)
    yes = sum(r.verdict == "stiction" for r in used)
    no = sum(r.verdict == "no_stiction" for r in used)
    n = len(used)
    score = (yes - no) / n if n else 0.0
    decision: Literal["stiction", "no_stiction", "undecided"]
    if yes >= p.min_votes and yes > no:
        decision = "stiction"
    elif no >= p.min_votes and no > yes:
        decision = "no_stiction"
    elif yes == no and yes >= p.min_votes:
        # A tie is broken by the tests that look at the waveform itself.
        shape = [r for r in used if r.name in SHAPE_TESTS]
        s_yes = sum(r.verdict == "stiction" for r in shape)
        s_no = sum(r.verdict == "no_stiction" for r in shape)
        decision = "stiction" if s_yes > s_no else "no_stiction" if s_no > s_yes else "undecided"
    else:
        decision = "undecided"
    return VoteResult(decision, yes, no, n, score)
