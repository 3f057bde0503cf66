"""The words every layer shares (contracts §2 and §5): loop types, causes, loop states and
action codes, each defined once.

``StrEnum`` members are ``str``: they compare equal to their value, go into the database and
into JSON as that value, and pydantic and typer accept and list them by value, so the
configuration, the CLI, the API's OpenAPI schema and the diagnosis all name the same set.
"""

from __future__ import annotations

from enum import StrEnum


class LoopType(StrEnum):
    """Kind of loop; it selects the applicable stiction tests (methods §3.3)."""

    flow = "flow"
    pressure = "pressure"
    level = "level"
    temperature = "temperature"
    composition = "composition"
    other = "other"


class Cause(StrEnum):
    """The diagnosis cause (contracts §2): the loop's one most likely problem."""

    ok = "ok"
    stiction = "stiction"
    aggressive_tuning = "aggressive_tuning"
    sluggish_tuning = "sluggish_tuning"
    external_disturbance = "external_disturbance"
    saturation = "saturation"
    oscillation_unknown_cause = "oscillation_unknown_cause"
    data_quality = "data_quality"
    manual_mode = "manual_mode"
    insufficient_data = "insufficient_data"
    deadband_backlash = "deadband_backlash"
    positioner_fault = "positioner_fault"
    positioner_tuning = "positioner_tuning"
    air_leakage = "air_leakage"
    actuator_undersized = "actuator_undersized"
    performance_degraded = "performance_degraded"
    """Variability far above the loop's own baseline with no cause found (issue 46)."""


class State(StrEnum):
    """A loop's health in the loop table (contracts §5)."""

    ok = "ok"
    warning = "warning"
    fault = "fault"
    unknown = "unknown"


class ActionCode(StrEnum):
    """The suggested action's code (contracts §2 ``actions[].code``)."""

    none = "none"
    valve_maintenance = "valve_maintenance"
    retune_less_aggressive = "retune_less_aggressive"
    retune_more_aggressive = "retune_more_aggressive"
    check_upstream = "check_upstream"
    check_valve_sizing = "check_valve_sizing"
    investigate_oscillation = "investigate_oscillation"
    check_data = "check_data"
    check_mode = "check_mode"
    check_linkage = "check_linkage"
    recalibrate_positioner = "recalibrate_positioner"
    retune_positioner = "retune_positioner"
    check_air_supply = "check_air_supply"
    check_actuator_sizing = "check_actuator_sizing"
    collect_more_data = "collect_more_data"
    investigate_degradation = "investigate_degradation"
    investigate = "investigate"


LOOP_TYPES: tuple[str, ...] = tuple(t.value for t in LoopType)
"""Every loop type's value, in the contract's order."""
CAUSES: tuple[str, ...] = tuple(c.value for c in Cause)
"""Every cause's value, in the contract's order."""
STATES: tuple[str, ...] = tuple(s.value for s in State)
"""Every loop state's value."""
