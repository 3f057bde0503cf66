"""The diagnosis result (contracts.md §2) and the suggested action for each cause."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from plantcheck.core.vocabulary import CAUSES, STATES, ActionCode, Cause, State

__all__ = ["CAUSES", "STATES", "Diagnosis", "action_for", "json_safe", "priority_of", "state_of"]

SCHEMA = "plantcheck.diagnosis/1"

_ACTIONS: dict[Cause, tuple[ActionCode, str]] = {
    Cause.ok: (ActionCode.none, "No action: the loop performs well."),
    Cause.stiction: (
        ActionCode.valve_maintenance,
        "Schedule valve maintenance: the control valve sticks (it moves in jumps, or not at all).",
    ),
    Cause.aggressive_tuning: (
        ActionCode.retune_less_aggressive,
        "Retune the controller less aggressively (lower gain or longer integral time): "
        "the loop oscillates at its own frequency.",
    ),
    Cause.sluggish_tuning: (
        ActionCode.retune_more_aggressive,
        "Retune the controller more aggressively (higher gain or shorter integral time): "
        "the loop recovers slowly from disturbances.",
    ),
    Cause.external_disturbance: (
        ActionCode.check_upstream,
        "Look upstream: an oscillating disturbance enters the loop from outside; "
        "find its source (other loops, feed, utilities).",
    ),
    Cause.saturation: (
        ActionCode.check_valve_sizing,
        "Check valve sizing and operating point: the controller output sits at a limit.",
    ),
    Cause.oscillation_unknown_cause: (
        ActionCode.investigate_oscillation,
        "Investigate the oscillation: the cause could not be determined from SP/PV/OP; "
        "a valve travel test or a short manual-mode test tells valve from disturbance.",
    ),
    Cause.data_quality: (
        ActionCode.check_data,
        "Check the measurement and historian settings (gaps, frozen or quantised values).",
    ),
    Cause.manual_mode: (
        ActionCode.check_mode,
        "Put the loop back in automatic, or find out why operators run it in manual.",
    ),
    Cause.deadband_backlash: (
        ActionCode.check_linkage,
        "Check the valve linkage and actuator for backlash: the stem lags OP reversals by a "
        "deadband without slip.",
    ),
    Cause.positioner_fault: (
        ActionCode.recalibrate_positioner,
        "Recalibrate the positioner (zero and span): the stem position is offset from OP.",
    ),
    Cause.positioner_tuning: (
        ActionCode.retune_positioner,
        "Retune the positioner: the stem hunts or overshoots on its own.",
    ),
    Cause.air_leakage: (
        ActionCode.check_air_supply,
        "Check the actuator for air leakage (diaphragm, tubing, supply): the stem drifts toward "
        "its fail position.",
    ),
    Cause.actuator_undersized: (
        ActionCode.check_actuator_sizing,
        "Check actuator size and air supply: the stem cannot move as fast as the controller asks.",
    ),
    Cause.insufficient_data: (
        ActionCode.collect_more_data,
        "Collect a longer, steady window (constant set point, automatic mode).",
    ),
}


_METHOD_WORDS = {
    "events": " from its stick-slip events",
    "ellipse": " (apparent stiction, from the PV(OP) ellipse)",
}


def action_for(
    cause: str, S: float | None = None, J: float | None = None, method: str | None = None
) -> dict[str, str]:
    """The suggested action (code and operator text) for ``cause``; a stiction size (% of
    travel) names its method unless it is the Hammerstein identification or measured."""
    code, text = (
        _ACTIONS[Cause(cause)]
        if cause in CAUSES
        else (ActionCode.investigate, "Investigate the loop.")
    )
    if cause == "deadband_backlash" and S is not None:
        text = f"{text[:-1]} (deadband {S:.1f} % of travel)."
    if cause == "stiction" and S is not None:
        jtxt = f" (J = {J:.1f} %)" if J is not None else ""
        how = _METHOD_WORDS.get(method or "", "")
        text = f"Schedule valve maintenance: estimated stiction S = {S:.1f} %{jtxt}{how}."
    return {"code": code.value, "text": text}


def json_safe(value: Any) -> Any:
    """JSON-safe copy: non-finite floats become None, floats are rounded to 6 significant digits."""
    if isinstance(value, float):
        if not math.isfinite(value):
            return None
        return float(f"{value:.6g}")
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


@dataclass
class Diagnosis:
    """One loop diagnosis, as fixed by contracts.md §2 (units: seconds, % of valve travel)."""

    loop_type: str
    chain: str
    samples: int
    sample_time_s: float
    cause: str
    confidence: float
    oscillating: bool
    oscillation: dict[str, float | None] | None = None
    oscillations: list[dict[str, float | None]] | None = None
    """Every oscillation found, the dominant first (contracts §2 optional field)."""
    stiction: dict[str, Any] = field(
        default_factory=lambda: {"detected": False, "S": None, "J": None, "tests": {}}
    )
    valve: dict[str, Any] | None = None
    indices: dict[str, float | int | None] = field(default_factory=dict)
    actions: list[dict[str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The contracts §2 JSON object."""
        return {
            "schema": SCHEMA,
            "loop_type": self.loop_type,
            "chain": self.chain,
            "samples": self.samples,
            "sample_time_s": json_safe(float(self.sample_time_s)),
            "cause": self.cause,
            "confidence": json_safe(round(float(self.confidence), 2)),
            "oscillating": self.oscillating,
            "oscillation": json_safe(self.oscillation),
            "oscillations": json_safe(self.oscillations),
            "stiction": json_safe(self.stiction),
            "valve": json_safe(self.valve),
            "indices": json_safe(self.indices),
            "actions": self.actions,
            "notes": self.notes,
        }


_FAULTS = frozenset(
    {
        Cause.stiction,
        Cause.aggressive_tuning,
        Cause.saturation,
        Cause.deadband_backlash,
        Cause.positioner_fault,
        Cause.positioner_tuning,
        Cause.air_leakage,
        Cause.actuator_undersized,
    }
)
_UNKNOWN = frozenset({Cause.data_quality, Cause.insufficient_data})


def state_of(cause: str) -> State:
    """Health state of a loop with this cause: ``ok``; ``fault`` when equipment or tuning is
    wrong and the loop performs badly (sticky or faulty valve, oscillating tuning, saturated
    valve); ``unknown`` when the window could not be judged; ``warning`` otherwise (sluggish
    tuning, an upstream disturbance, an oscillation of unknown cause, manual mode)."""
    if cause == Cause.ok:
        return State.ok
    if cause in _FAULTS:
        return State.fault
    if cause in _UNKNOWN:
        return State.unknown
    return State.warning


def priority_of(cause: str) -> int:
    """Priority of the suggested action: 1 (fault), 2 (warning), 3 (unknown or ok)."""
    return {State.fault: 1, State.warning: 2}.get(state_of(cause), 3)
