"""Common result type of the stiction tests and the vote vocabulary."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Verdict = Literal["stiction", "no_stiction", "undecided", "not_applicable"]


@dataclass(frozen=True)
class StictionTestResult:
    """One stiction test on one window.

    ``value`` is the test's index (dimensionless unless the test says otherwise), ``verdict``
    its reading against the thresholds, ``detail`` a short human-readable explanation.
    ``label`` replaces the numeric value in reports where the method is read as a shape
    (Horch: ``odd``/``even``/``undecided``).
    """

    name: str
    value: float | None
    verdict: Verdict
    detail: str = ""
    label: str | None = None


def three_way(value: float, yes_above: float, no_below: float) -> Verdict:
    """Map an index to stiction / no_stiction / undecided with a dead band in between."""
    if value >= yes_above:
        return "stiction"
    if value <= no_below:
        return "no_stiction"
    return "undecided"
