"""The diagnosis result (contracts.md §2) and the suggested action for each cause."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

SCHEMA = "plantcheck.diagnosis/1"

CAUSES = (
    "ok",
    "stiction",
    "aggressive_tuning",
    "sluggish_tuning",
    "external_disturbance",
    "saturation",
    "oscillation_unknown_cause",
    "data_quality",
    "manual_mode",
    "insufficient_data",
    "deadband_backlash",
    "positioner_fault",
    "positioner_tuning",
    "air_leakage",
    "actuator_undersized",
)

_ACTIONS: dict[str, tuple[str, str]] = {
    "ok": ("none", "No action: the loop performs well."),
    "stiction": (
        "valve_maintenance",
        "Schedule valve maintenance: the control valve sticks (it moves in jumps, or not at all).",
    ),
    "aggressive_tuning": (
        "retune_less_aggressive",
        "Retune the controller less aggressively (lower gain or longer integral time): "
        "the loop oscillates at its own frequency.",
    ),
    "sluggish_tuning": (
        "retune_more_aggressive",
        "Retune the controller more aggressively (higher gain or shorter integral time): "
        "the loop recovers slowly from disturbances.",
    ),
    "external_disturbance": (
        "check_upstream",
        "Look upstream: an oscillating disturbance enters the loop from outside; "
        "find its source (other loops, feed, utilities).",
    ),
    "saturation": (
        "check_valve_sizing",
        "Check valve sizing and operating point: the controller output sits at a limit.",
    ),
    "oscillation_unknown_cause": (
        "investigate_oscillation",
        "Investigate the oscillation: the cause could not be determined from SP/PV/OP; "
        "a valve travel test or a short manual-mode test tells valve from disturbance.",
    ),
    "data_quality": (
        "check_data",
        "Check the measurement and historian settings (gaps, frozen or quantised values).",
    ),
    "manual_mode": (
        "check_mode",
        "Put the loop back in automatic, or find out why operators run it in manual.",
    ),
    "deadband_backlash": (
        "check_linkage",
        "Check the valve linkage and actuator for backlash: the stem lags OP reversals by a "
        "deadband without slip.",
    ),
    "positioner_fault": (
        "recalibrate_positioner",
        "Recalibrate the positioner (zero and span): the stem position is offset from OP.",
    ),
    "positioner_tuning": (
        "retune_positioner",
        "Retune the positioner: the stem hunts or overshoots on its own.",
    ),
    "air_leakage": (
        "check_air_supply",
        "Check the actuator for air leakage (diaphragm, tubing, supply): the stem drifts toward "
        "its fail position.",
    ),
    "actuator_undersized": (
        "check_actuator_sizing",
        "Check actuator size and air supply: the stem cannot move as fast as the controller asks.",
    ),
    "insufficient_data": (
        "collect_more_data",
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
    code, text = _ACTIONS.get(cause, ("investigate", "Investigate the loop."))
    if cause == "deadband_backlash" and S is not None:
        text = f"{text[:-1]} (deadband {S:.1f} % of travel)."
    if cause == "stiction" and S is not None:
        jtxt = f" (J = {J:.1f} %)" if J is not None else ""
        how = _METHOD_WORDS.get(method or "", "")
        text = f"Schedule valve maintenance: estimated stiction S = {S:.1f} %{jtxt}{how}."
    return {"code": code, "text": text}


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


STATES = ("ok", "warning", "fault", "unknown")
"""Loop states of the health table (contracts §5)."""

_FAULTS = frozenset(
    {
        "stiction",
        "aggressive_tuning",
        "saturation",
        "deadband_backlash",
        "positioner_fault",
        "positioner_tuning",
        "air_leakage",
        "actuator_undersized",
    }
)
_UNKNOWN = frozenset({"data_quality", "insufficient_data"})


def state_of(cause: str) -> str:
    """Health state of a loop with this cause: ``ok``; ``fault`` when equipment or tuning is
    wrong and the loop performs badly (sticky or faulty valve, oscillating tuning, saturated
    valve); ``unknown`` when the window could not be judged; ``warning`` otherwise (sluggish
    tuning, an upstream disturbance, an oscillation of unknown cause, manual mode)."""
    if cause == "ok":
        return "ok"
    if cause in _FAULTS:
        return "fault"
    if cause in _UNKNOWN:
        return "unknown"
    return "warning"


def priority_of(cause: str) -> int:
    """Priority of the suggested action: 1 (fault), 2 (warning), 3 (unknown or ok)."""
    return {"fault": 1, "warning": 2}.get(state_of(cause), 3)
