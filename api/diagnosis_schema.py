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


class ProcessModelJSON(_Part):
    """The process identified from OP to PV (issue 48)."""

    type: Literal["fopdt", "ipdt"] | None = Field(
        description="fopdt: first order plus dead time; ipdt: integrator plus dead time."
    )
    K: float | None = Field(
        description="Gain: PV units per % of OP (ipdt: PV units per s per % of OP)."
    )
    tau_s: float | None = Field(description="Time constant, s (fopdt).")
    theta_s: float | None = Field(description="Dead time, s.")
    fit_percent: float | None = Field(description="Simulated-output fit, %.")
    K_sd: float | None = None
    tau_sd: float | None = None
    theta_sd: float | None = None
    source: str | None = Field(None, description="'set-point steps' or 'routine'.")


class ControllerJSON(_Part):
    """An ideal-form PI(D): Kc in % of OP per PV unit (positive: reverse acting), Ti and Td
    in s; a proposal also names its method and closed-loop time constant."""

    Kc: float | None
    Ti_s: float | None
    Td_s: float | None = None
    method: str | None = None
    tau_c_s: float | None = None


class SensitivityJSON(_Part):
    """|S(jω)| = |1/(1 + L(jω))| of the loop at ``w_rad_s`` (rad/s): its peak is Ms."""

    w_rad_s: list[float]
    mag: list[float]


class ResponseJSON(_Part):
    """A predicted closed-loop response: PV after a unit set-point step (``sp``) and after a
    load step worth one PV unit (``load``), at times ``t_s``."""

    t_s: list[float]
    sp: list[float]
    load: list[float]


class PredictionJSON(_Part):
    """What the proposal will do on the identified process."""

    iae_ratio: float | None = Field(
        description="Error integral (set-point plus load step), proposed / present."
    )
    gain_margin: float | None = Field(description="Gain margin of the proposal (times).")
    ms: float | None = Field(description="Maximum sensitivity of the proposal.")
    phase_margin_deg: float | None = None
    current: dict[str, float | None] | None = None
    proposed_response: ResponseJSON | None = None
    current_response: ResponseJSON | None = None
    proposed_sensitivity: SensitivityJSON | None = None
    current_sensitivity: SensitivityJSON | None = None


class DcsJSON(_Part):
    """The proposal in the loop's configured controller form."""

    form: Literal["ideal", "parallel", "series"]
    gain: float
    gain_unit: str
    integral: float
    integral_unit: str
    derivative: float | None = None
    derivative_unit: str | None = None
    action: Literal["reverse", "direct"]
    note: str | None = None


class OpLimitJSON(_Part):
    """The output limit OP rests at and the share of the window it rests there."""

    value: float
    share: float


class KpisJSON(_Part):
    """The window's performance indices (contracts §2 ``kpis``, issue 49)."""

    service_factor: float | None = Field(description="Share of the window in automatic.")
    op_limit: OpLimitJSON | None = None
    harris_index: float | None = Field(
        description="Minimum variance over the error's variance (1 = minimum variance)."
    )
    dead_time_s: float | None = Field(description="The dead time the Harris index used, s.")
    dead_time_source: str | None = None
    harris_note: str | None = None
    error_mean: float | None = Field(description="Mean of SP − PV, PV units.")
    error_std: float | None = Field(description="Standard deviation of SP − PV, PV units.")
    variability_ratio: float | None = Field(
        description="The detrended error's σ over the loop's healthy baseline σ."
    )
    op_travel_per_day: float | None = Field(description="OP travel, % of travel per day.")
    op_reversals_per_day: float | None = Field(description="OP reversals per day.")
    mv_travel_per_day: float | None = None
    mv_reversals_per_day: float | None = None


class TuningJSON(_Part):
    """Identification and retuning (contracts §2 ``tuning``, issue 48)."""

    model: ProcessModelJSON | None
    current: ControllerJSON | None
    proposed: ControllerJSON | None
    alternative: ControllerJSON | None = None
    predicted: PredictionJSON | None
    dcs: DcsJSON | None
    note: str | None = None


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
    kpis: KpisJSON | None = None
    """The window's performance indices (issue 49)."""
    tuning: TuningJSON | None = None
    """For a tuning cause: the identified process, the present and proposed controller and
    the prediction; for a valve cause: why there is no proposal (issue 48)."""
