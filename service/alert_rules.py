"""Which confirmed verdict changes alert whom (issue 49 item 4): the configured rules as they
apply to each loop, and the drafts a change gives (stored with it, ``storage.alerts``).

Kept apart from the dispatcher (``alerts.py``) so that the scheduler does not import the HTTP
and SMTP clients.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from plantcheck.diagnosis.priority import DEFAULT_CRITICALITY
from plantcheck.service.alert_config import AlertRule
from plantcheck.storage.alerts import AlertDraft

SCHEMA = "plantcheck.alert/1"
"""The schema name every alert's JSON carries."""


@dataclass(frozen=True)
class LoopAlertRule:
    """A rule as it applies to one loop (its loop, area and criticality filters passed)."""

    name: str
    targets: tuple[str, ...]
    states: frozenset[str]
    causes: frozenset[str]
    quiet_s: float


def rules_for_loop(
    rules: Iterable[AlertRule], loop: str, area: str, criticality: int | None
) -> tuple[LoopAlertRule, ...]:
    """The rules whose loop, area and criticality filters let ``loop`` through."""
    crit = DEFAULT_CRITICALITY if criticality is None else criticality
    return tuple(
        LoopAlertRule(
            r.name,
            tuple(r.targets),
            frozenset(str(s) for s in r.states),
            frozenset(str(c) for c in r.causes),
            r.quiet_period_s,
        )
        for r in rules
        if (not r.loops or loop in r.loops)
        and (not r.areas or area in r.areas)
        and crit >= r.min_criticality
    )


def drafts_for(rules: Sequence[LoopAlertRule], facts: dict[str, Any]) -> tuple[AlertDraft, ...]:
    """The alerts a verdict change (``facts``: loop, state, cause, action, since, area,
    criticality) sends: one per target of each rule its state and cause pass."""
    return tuple(
        AlertDraft(
            r.name,
            target,
            int(r.quiet_s * 1e6),
            {"schema": SCHEMA, **facts, "rule": r.name, "target": target},
        )
        for r in rules
        if facts["state"] in r.states and (not r.causes or facts["cause"] in r.causes)
        for target in r.targets
    )
