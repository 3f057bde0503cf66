"""The diagnosis object of contracts §2 as the API serves it: pydantic models of the stored
JSON, so that ``/openapi.json`` describes every field a client reads.

The chains' ``Diagnosis`` (``diagnosis/result.py``) is the frozen dataclass the service works
with; the store keeps its ``to_dict()`` JSON, and these models validate that JSON on the way
out. Unknown keys pass through (``extra="allow"``): an older or newer payload is served as
stored, and clients ignore what they do not know (contracts §2).
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from plantcheck.core.vocabulary import ActionCode, Cause, LoopType


class _Part(BaseModel):
    model_config = ConfigDict(extra="allow", populate_by_name=True)


class OscillationJSON(_Part):
    """The dominant oscillation of the control error (or of OP)."""

    period_s: float | None = Field(description="Period, s.")
    amplitude: float | None = Field(description="Amplitude, signal units.")
    regularity: float | None = Field(description="ACF regularity (Thornhill r).")


class OscillationComponentJSON(OscillationJSON):
    """One oscillation found, dominant first."""

    power_share: float | None = Field(None, description="Share of the signal's power.")


class EventJSON(_Part):
    """A stick-slip event; times in s from the window's first sample."""

    start: float
    end: float
    op_travel: float = Field(description="OP travel at breakaway, %.")
    pv_jump: float = Field(description="PV jump, PV units (signed).")


class EstimateJSON(_Part):
    """The best stiction size available, % of valve travel."""

    S: float | None
    J: float | None
    method: Literal["hammerstein", "events", "ellipse", "measured"]
    reliable: bool


class VoteJSON(_Part):
    """The stiction tests' vote."""

    decision: str
    n_for: int = Field(alias="for")
    against: int
    tests: int


class QuantificationJSON(_Part):
    """The Hammerstein identification behind S and J (methods §6.1)."""

    reliable: bool
    model: str | None = None
    fit_percent: float | None = None
    S_best: float | None = None
    J_best: float | None = None
    reasons: list[str] = []
    reason_codes: list[str] = []
    external_period_s: float | None = None
    period_s: float | None = None


class StictionJSON(_Part):
    """The stiction part: S and J the Hammerstein (or measured) estimate, % of travel."""

    detected: bool
    S: float | None = None
    J: float | None = None
    tests: dict[str, float | str | None] = {}
    votes: dict[str, str] | None = None
    vote: VoteJSON | None = None
    events: list[EventJSON] | None = None
    estimate: EstimateJSON | None = None
    quantification: QuantificationJSON | None = None
    apparent: float | None = Field(None, description="Apparent stiction of the PV(OP) ellipse.")
    source: str | None = Field(None, description="mv: measured from the stem position.")
    op_pv_estimate: dict[str, float | bool | None] | None = None


class ValveJSON(_Part):
    """The advanced chain's valve verdict."""

    state: str
    kpis: dict[str, float | None] = {}


class ActionJSON(_Part):
    """A suggested action."""

    code: ActionCode
    text: str


class EvidenceJSON(_Part):
    """One input of the learned decision and what it contributed to the cause's raw score."""

    name: str
    value: float | None
    contribution: float


class DiagnosisJSON(_Part):
    """One loop diagnosis (contracts §2)."""

    schema_id: Literal["plantcheck.diagnosis/1"] = Field(alias="schema")
    loop_type: LoopType
    chain: Literal["standard", "advanced"]
    samples: int
    sample_time_s: float
    cause: Cause
    confidence: float | None
    oscillating: bool
    oscillation: OscillationJSON | None = None
    oscillations: list[OscillationComponentJSON] | None = None
    stiction: StictionJSON
    valve: ValveJSON | None = None
    indices: dict[str, int | float | None] = {}
    actions: list[ActionJSON] = []
    notes: list[str] = []
    probabilities: dict[str, float] | None = None
    """Each cause's calibrated probability (the learned model, issue 46)."""
    evidence: list[EvidenceJSON] | None = None
    """The inputs that moved the decision most, largest contribution first."""
