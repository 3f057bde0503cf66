"""The diagnosis result (contracts.md §2) and the suggested action for each cause."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any

from plantcheck.core.vocabulary import CAUSES, STATES, ActionCode, Cause, State

__all__ = [
    "CAUSES",
    "STATES",
    "Action",
    "Diagnosis",
    "DiagnosisDraft",
    "StictionOut",
    "action_for",
    "json_safe",
    "priority_of",
    "state_of",
]

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
    Cause.performance_degraded: (
        ActionCode.investigate_degradation,
        "Investigate: the control error varies far more than in the loop's own healthy weeks, "
        "and no cause shows in this window.",
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


@dataclass(frozen=True)
class Action:
    """A suggested action: its code (``ActionCode``) and the operator's text."""

    code: str
    text: str


@dataclass(frozen=True)
class OscillationSummary:
    """The dominant oscillation: period (s), amplitude (signal units), regularity."""

    period_s: float | None
    amplitude: float | None
    regularity: float | None


@dataclass(frozen=True)
class OscillationComponent:
    """One oscillation found (contracts §2 ``oscillations``): period (s), amplitude, ACF
    regularity after band-pass (None from the few-cycle test), share of the signal's power."""

    period_s: float | None
    amplitude: float | None
    regularity: float | None
    power_share: float | None


@dataclass(frozen=True)
class EventOut:
    """A stick-slip event (contracts §2 ``stiction.events``): start and end in s from the
    window's first sample, OP travel at breakaway (%), PV jump (PV units)."""

    start: float
    end: float
    op_travel: float
    pv_jump: float


@dataclass(frozen=True)
class SizeEstimate:
    """The best stiction size available (contracts §2 ``stiction.estimate``), % of travel."""

    S: float | None
    J: float | None
    method: str
    """``hammerstein``, ``events``, ``ellipse`` (or ``measured`` from MV)."""
    reliable: bool


@dataclass(frozen=True)
class VoteOut:
    """The stiction tests' vote: decision and the counts for, against and voting."""

    decision: str
    n_for: int
    n_against: int
    tests: int


@dataclass(frozen=True)
class QuantificationOut:
    """The Hammerstein identification behind ``S`` and ``J`` (methods §6.1)."""

    reliable: bool
    model: str
    fit_percent: float | None
    S_best: float | None
    J_best: float | None
    reasons: tuple[str, ...]
    reason_codes: tuple[str, ...]
    external_period_s: float | None
    period_s: float | None


@dataclass(frozen=True)
class StictionOut:
    """The stiction part (contracts §2 ``stiction``): ``S``/``J`` the Hammerstein (or, from
    the advanced chain, measured) estimate in % of travel; the optional parts None when not
    computed."""

    detected: bool = False
    S: float | None = None
    J: float | None = None
    tests: Mapping[str, float | str | None] = field(default_factory=dict)
    votes: Mapping[str, str] | None = None
    vote: VoteOut | None = None
    events: tuple[EventOut, ...] | None = None
    estimate: SizeEstimate | None = None
    quantification: QuantificationOut | None = None
    apparent: float | None = None
    """Apparent stiction of the PV(OP) ellipse, % of OP (ranks valves; not S)."""
    source: str | None = None
    """``mv`` when S and J were measured from the stem position."""
    op_pv_estimate: Mapping[str, float | bool | None] | None = None
    """The OP/PV-only estimate beside a measured one (advanced chain)."""


@dataclass(frozen=True)
class ValveOut:
    """The advanced chain's valve verdict from OP and MV: state and its indicators."""

    state: str
    kpis: Mapping[str, float | None]


@dataclass(frozen=True)
class Diagnosis:
    """One loop diagnosis, as fixed by contracts.md §2 (units: seconds, % of valve travel):
    frozen, every part typed; ``to_dict`` gives the JSON object."""

    loop_type: str
    chain: str
    samples: int
    sample_time_s: float
    cause: str
    confidence: float
    oscillating: bool
    oscillation: OscillationSummary | None = None
    oscillations: tuple[OscillationComponent, ...] | None = None
    """Every oscillation found, the dominant first (contracts §2 optional field)."""
    stiction: StictionOut = field(default_factory=StictionOut)
    valve: ValveOut | None = None
    indices: Mapping[str, float | int | None] = field(default_factory=dict)
    """The chain's indices (``idle_index``, ``hagglund_load_count``, ``saturation_fraction``,
    ``sp_step_slowness``, ...), by name."""
    actions: tuple[Action, ...] = ()
    notes: tuple[str, ...] = ()
    probabilities: Mapping[str, float] | None = None
    """Each cause's calibrated probability (contracts §2 optional field): the learned
    decision's; None where the rules decided."""
    evidence: tuple[Mapping[str, Any], ...] | None = None
    """The inputs that moved the decision most, ``{"name", "value", "contribution"}``,
    largest contribution first (contracts §2 optional field)."""
    kpis: Mapping[str, Any] | None = None
    """The window's performance indices (contracts §2 ``kpis``, ``diagnosis/kpis.py``)."""
    tuning: Mapping[str, Any] | None = None
    """The identified process, present and proposed controller and the prediction for a
    tuning cause; why there is no proposal for a valve cause (contracts §2 ``tuning``)."""
    controller_change: Mapping[str, Any] | None = None
    """A retuning inside the window (``controller_change.py``): ``at_s`` (s from the window's
    first sample), the PI settings ``before`` and ``after``; the window is judged from it on
    (contracts §2 optional field)."""

    def with_notes_first(self, notes: Sequence[str]) -> Diagnosis:
        """The same diagnosis with ``notes`` before its own (the record's or the store's)."""
        return replace(self, notes=(*notes, *self.notes))

    def to_dict(self) -> dict[str, Any]:
        """The contracts §2 JSON object (optional parts left out when not computed)."""
        return {
            "schema": SCHEMA,
            "loop_type": self.loop_type,
            "chain": self.chain,
            "samples": self.samples,
            "sample_time_s": json_safe(float(self.sample_time_s)),
            "cause": self.cause,
            "confidence": json_safe(round(float(self.confidence), 2)),
            "oscillating": self.oscillating,
            "oscillation": json_safe(_plain(self.oscillation)),
            "oscillations": json_safe(_plain(self.oscillations)),
            "stiction": json_safe(_stiction_json(self.stiction)),
            "valve": json_safe(_plain(self.valve)),
            "indices": json_safe(dict(self.indices)),
            "actions": [{"code": a.code, "text": a.text} for a in self.actions],
            "notes": list(self.notes),
            **(
                {"probabilities": json_safe(dict(self.probabilities))}
                if self.probabilities is not None
                else {}
            ),
            **({"evidence": json_safe(_plain(self.evidence))} if self.evidence is not None else {}),
            **({"kpis": json_safe(_plain(self.kpis))} if self.kpis is not None else {}),
            **({"tuning": json_safe(_plain(self.tuning))} if self.tuning is not None else {}),
            **(
                {"controller_change": json_safe(_plain(self.controller_change))}
                if self.controller_change is not None
                else {}
            ),
        }


def _plain(value: Any) -> Any:
    """Dataclasses, mappings and tuples as JSON's dicts and lists."""
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _stiction_json(st: StictionOut) -> dict[str, Any]:
    """``stiction`` of contracts §2: detected, S, J and tests always; the optional parts when
    computed (the vote's counts under the keys ``for`` and ``against``)."""
    out: dict[str, Any] = {"detected": st.detected, "S": st.S, "J": st.J, "tests": dict(st.tests)}
    for name in ("votes", "events", "estimate", "quantification", "apparent", "source"):
        value = getattr(st, name)
        if value is not None:
            out[name] = _plain(value)
    if st.vote is not None:
        v = st.vote
        out["vote"] = {"decision": v.decision, "for": v.n_for, "against": v.n_against,
                       "tests": v.tests}  # fmt: skip
    if st.op_pv_estimate is not None:
        out["op_pv_estimate"] = dict(st.op_pv_estimate)
    return out


@dataclass
class DiagnosisDraft:
    """The diagnosis while a chain builds it (mutable, parts as dicts); ``freeze`` gives the
    typed, frozen ``Diagnosis`` the chains return."""

    loop_type: str
    chain: str
    samples: int
    sample_time_s: float
    cause: str
    confidence: float
    oscillating: bool
    oscillation: dict[str, float | None] | None = None
    oscillations: list[dict[str, float | None]] | None = None
    stiction: dict[str, Any] = field(
        default_factory=lambda: {"detected": False, "S": None, "J": None, "tests": {}}
    )
    valve: dict[str, Any] | None = None
    indices: dict[str, float | int | None] = field(default_factory=dict)
    actions: list[dict[str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    probabilities: dict[str, float] | None = None
    evidence: list[dict[str, Any]] | None = None
    tuning: dict[str, Any] | None = None
    kpis: dict[str, Any] | None = None
    controller_change: dict[str, Any] | None = None

    def freeze(self) -> Diagnosis:
        """The typed, frozen diagnosis of this draft."""
        return Diagnosis(
            loop_type=self.loop_type,
            chain=self.chain,
            samples=self.samples,
            sample_time_s=self.sample_time_s,
            cause=self.cause,
            confidence=self.confidence,
            oscillating=self.oscillating,
            oscillation=OscillationSummary(**self.oscillation) if self.oscillation else None,
            oscillations=(
                tuple(OscillationComponent(**c) for c in self.oscillations)
                if self.oscillations is not None
                else None
            ),
            stiction=_stiction_of(self.stiction),
            valve=ValveOut(self.valve["state"], dict(self.valve["kpis"])) if self.valve else None,
            indices=dict(self.indices),
            actions=tuple(Action(a["code"], a["text"]) for a in self.actions),
            notes=tuple(self.notes),
            probabilities=dict(self.probabilities) if self.probabilities is not None else None,
            evidence=tuple(self.evidence) if self.evidence is not None else None,
            tuning=self.tuning,
            kpis=self.kpis,
            controller_change=self.controller_change,
        )


def _stiction_of(st: dict[str, Any]) -> StictionOut:
    vote = st.get("vote")
    q = st.get("quantification")
    est = st.get("estimate")
    events = st.get("events")
    return StictionOut(
        detected=bool(st.get("detected", False)),
        S=st.get("S"),
        J=st.get("J"),
        tests=dict(st.get("tests") or {}),
        votes=dict(st["votes"]) if st.get("votes") is not None else None,
        vote=(
            VoteOut(vote["decision"], vote["for"], vote["against"], vote["tests"])
            if vote is not None
            else None
        ),
        events=tuple(EventOut(**e) for e in events) if events is not None else None,
        estimate=SizeEstimate(**est) if est is not None else None,
        quantification=(
            QuantificationOut(
                reliable=q["reliable"],
                model=q["model"],
                fit_percent=q["fit_percent"],
                S_best=q["S_best"],
                J_best=q["J_best"],
                reasons=tuple(q["reasons"]),
                reason_codes=tuple(q.get("reason_codes") or ()),
                external_period_s=q["external_period_s"],
                period_s=q["period_s"],
            )
            if q is not None
            else None
        ),
        apparent=st.get("apparent"),
        source=st.get("source"),
        op_pv_estimate=dict(st["op_pv_estimate"]) if st.get("op_pv_estimate") else None,
    )


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
