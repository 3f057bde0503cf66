"""How urgently a loop needs attention: one number to put the worst loops first (issue 49).

A plant with hundreds of loops is worked through from the top of a list ordered by what a bad
loop costs: how bad it is (its state, and how far its performance indices are from healthy)
times how much it matters (the loop's criticality). This is the ranking large-scale
assessment programmes use (Paulonis & Cox 2003: performance figures weighted by the loop's
economic importance; Jelali 2006, section 7, on prioritising loops by impact), with a simple,
readable combination:

    priority = 100 · (criticality / 5) · (0.7 · severity(state) + 0.3 · distance(kpis))

- ``severity``: fault 1, warning 0.6, unknown 0.2 (not judged yet or not judgeable), ok 0.
- ``distance`` (0-1) is the largest of four shortfalls, each 0 when healthy and 1 when far
  off: variability over the loop's own baseline (1 at 1×, 1 at 5×), the Harris index below
  0.5 (0 at ≥ 0.5, 1 at 0), the time in manual (1 − service factor), and the time at an output
  limit (its share).
- ``criticality`` 1-5 from the configuration, 3 when not given.

From 0 (an ``ok`` loop whose indices are healthy) to 100 (a loop of criticality 5 in fault and
far from its normal); an ``ok`` loop whose indices drift rises above 0 before its state changes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

DEFAULT_CRITICALITY = 3
"""A loop's criticality when the configuration does not give one (the middle of 1-5)."""

SEVERITY = {"fault": 1.0, "warning": 0.6, "unknown": 0.2, "ok": 0.0}
"""How bad each state is, 0-1."""

STATE_WEIGHT = 0.7
"""The state's share of the priority; the indices' distance from healthy has the rest."""


def _clip01(x: float) -> float:
    return min(1.0, max(0.0, x))


def kpi_distance(kpis: Mapping[str, Any] | None) -> float:
    """How far the indices are from healthy, 0 (healthy or unknown) to 1 (far off): the largest
    shortfall of variability, Harris index, service factor and time at an output limit."""
    if not kpis:
        return 0.0
    shortfalls = [0.0]
    ratio = kpis.get("variability_ratio")
    if ratio is not None:
        shortfalls.append(_clip01((float(ratio) - 1.0) / 4.0))
    harris = kpis.get("harris_index")
    if harris is not None:
        shortfalls.append(_clip01((0.5 - float(harris)) / 0.5))
    service = kpis.get("service_factor")
    if service is not None:
        shortfalls.append(_clip01(1.0 - float(service)))
    limit = kpis.get("op_limit")
    if isinstance(limit, Mapping) and limit.get("share") is not None:
        shortfalls.append(_clip01(float(limit["share"])))
    return max(shortfalls)


def loop_priority(
    state: str, criticality: int | None = None, kpis: Mapping[str, Any] | None = None
) -> float:
    """The loop's priority, 0-100 (higher: look at it sooner), to 0.1."""
    crit = DEFAULT_CRITICALITY if criticality is None else min(5, max(1, int(criticality)))
    badness = STATE_WEIGHT * SEVERITY.get(state, 0.2) + (1 - STATE_WEIGHT) * kpi_distance(kpis)
    return round(100.0 * crit / 5.0 * badness, 1)
