"""Response models of the REST API (contracts §5). Times are ISO 8601 UTC strings."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from plantcheck.api.diagnosis_schema import DiagnosisJSON, KpisJSON
from plantcheck.core.vocabulary import ActionCode, Cause, LoopType, State

__all__ = ["State"]  # re-exported for the routes' filters


class LoopOut(BaseModel):
    """A row of the loop-health table."""

    id: str
    type: LoopType
    source: str
    description: str = ""
    state: State
    cause: Cause | None = Field(description="Cause of the current verdict (contracts §2).")
    since: str | None = Field(description="When the current verdict began (ISO 8601 UTC).")
    last_diagnosis_at: str | None
    S: float | None = Field(description="Latest stiction estimate, % of valve travel.")
    J: float | None = Field(description="Latest slip jump estimate, % of valve travel.")
    S_method: str | None = Field(
        None,
        description="How S and J were estimated (hammerstein, measured, events, ellipse): the "
        "latest reliable estimate of the most direct method the valve has.",
    )
    S_at: str | None = Field(
        None,
        description="When S and J were estimated (ISO 8601 UTC, the end of the window they "
        "came from): their age.",
    )
    priority: float = Field(
        0.0,
        description="How urgently the loop needs attention, 0-100: its state and how far its "
        "indices are from healthy, weighed by its criticality (README, 'Priority').",
    )
    criticality: int | None = Field(
        None, description="How much the loop matters, 1-5 (configuration; 3 when unset)."
    )
    area: str = Field("", description="The plant area (configuration).")
    unit: str = Field("", description="The process unit (configuration).")
    kpis: KpisJSON | None = Field(
        None, description="The indices of the latest diagnosis (contracts §2 `kpis`)."
    )


class LoopDetail(LoopOut):
    """A loop and its latest diagnosis."""

    diagnosis: DiagnosisJSON | None = Field(
        description="The latest diagnosis, the object of contracts §2 (null before the first)."
    )
    window_start: str | None = None
    window_end: str | None = None


class DiagnosisOut(BaseModel):
    """One stored diagnosis."""

    created_at: str
    window_start: str
    window_end: str
    cause: Cause
    state: State
    diagnosis: DiagnosisJSON = Field(description="The object of contracts §2.")


class SampleOut(BaseModel):
    """One stored sample (value null when its quality was Bad), or with ``resolution=hour``
    one hour of a signal's Good samples (value = their mean)."""

    time: str = Field(description="Source timestamp, ISO 8601 UTC (hourly: the hour's start).")
    signal: Literal["sp", "pv", "op", "mv", "mode"]
    value: float | None
    status: int = Field(description="OPC UA status code (0 = Good).")
    received_at: str | None = Field(description="When it was received (null for hourly rows).")
    count: int | None = Field(None, description="Hourly rows: Good samples in the hour.")
    min: float | None = Field(None, description="Hourly rows: the lowest Good value.")
    max: float | None = Field(None, description="Hourly rows: the highest Good value.")


class ActionOut(BaseModel):
    """A row of the suggested-action table."""

    loop: str
    cause: Cause
    code: ActionCode
    action: str = Field(description="What to do, for the operator.")
    priority: int = Field(description="1 fault, 2 warning, 3 other.")
    since: str


class StictionPoint(BaseModel):
    time: str
    S: float = Field(description="% of valve travel.")
    J: float | None
    source: Literal["op_pv", "mv"] = Field(description="From OP/PV or from the stem position.")
    method: Literal["hammerstein", "events", "ellipse", "measured"] = Field(
        "hammerstein",
        description="How S was estimated: Hammerstein identification, stick-slip events, "
        "PV(OP) ellipse (apparent stiction), or measured from the stem position.",
    )
    reliable: bool = Field(True, description="The estimate passed its method's rules.")


class WeekOut(BaseModel):
    week_start: str
    S_median: float
    J_median: float | None
    estimates: int


class ValveReport(BaseModel):
    """One valve's stiction history and trend (Theil–Sen; Bacci di Capaci & Scali 2014)."""

    loop: str
    limit: float = Field(description="S (% of travel) at which maintenance is due.")
    current_S: float | None
    current_J: float | None
    slope_per_week: float | None = Field(description="Trend of S, % of travel per week.")
    above_limit: bool
    projected_crossing: str | None = Field(description="When S is projected to pass the limit.")
    note: str
    trend_method: str | None = Field(
        None,
        description="The one method whose reliable estimates make the trend, the weekly "
        "medians and the current S (methods are never mixed); null without any estimate.",
    )
    latest_S: float | None = Field(
        None,
        description="The valve's S as the loop table shows it (GET /loops S): its latest "
        "reliable estimate of the most direct method, % of travel.",
    )
    latest_J: float | None = Field(None, description="J with latest_S, % of travel.")
    latest_method: str | None = Field(None, description="The method of latest_S (S_method).")
    latest_at: str | None = Field(None, description="When latest_S was estimated (S_at).")
    action: str | None = Field(
        None, description="The loop's open action, as GET /actions gives it (null: none)."
    )
    weeks: list[WeekOut]
    estimates: list[StictionPoint]


class StictionReport(BaseModel):
    generated_at: str
    start: str | None
    end: str | None
    valves: list[ValveReport]


class Readiness(BaseModel):
    ready: bool
    storage: bool = Field(
        description="The database answers reads and takes this process's sample commits."
    )
    scheduler: bool
    sources: bool = Field(description="No source down past its grace period (down_grace_s).")
    sources_down: list[str] = Field(default=[], description="Sources down past their grace.")
    role: Literal["single", "leader", "standby"] = Field(
        "single",
        description="single: the only process (SQLite); leader: holds the scheduler lock "
        "(PostgreSQL); standby: serves the API and takes over when the leader stops.",
    )
    storage_writes: bool = Field(
        True, description="Sample commits succeed (false while the database refuses writes)."
    )
    buffer: bool = Field(
        True, description="The durable buffer takes what the database cannot (false: failing)."
    )
    problems: list[str] = Field(
        default=[], description="What is not ready, one sentence each (storage, buffer, ...)."
    )


class StorageOut(BaseModel):
    """Where this process's samples go: the database, the durable buffer, memory."""

    ingesting: bool = Field(description="This process collects samples (false: API only).")
    database: Literal["up", "down"] = Field(description="down: sample commits fail.")
    database_since: str | None = Field(description="When commits began to fail.")
    database_error: str = Field(description="The most recent commit failure, empty if none.")
    buffer: Literal["up", "down"] = Field(description="down: the durable buffer's disk fails.")
    buffer_since: str | None = Field(description="When the buffer began to fail.")
    buffer_error: str = Field(description="The most recent buffer failure, empty if none.")
    buffer_path: str
    samples_in_buffer: int
    samples_in_memory: int = Field(
        description="Held in memory while the database does not take them (0 while it does)."
    )
    memory_max_samples: int
    samples_dropped: int = Field(description="Lost since start (buffer or memory full).")
    samples_stored: int


class SourceOut(BaseModel):
    """A data source's health (contracts §5)."""

    name: str
    protocol: Literal["modbus", "opcua"]
    state: Literal["up", "down", "unknown"]
    since: str | None = Field(description="When the state began (down: first failure).")
    last_good_sample_at: str | None
    failures: int = Field(description="Failed connections or reads since the service started.")
    last_error: str = Field(description="The most recent failure, empty if none.")


class Health(BaseModel):
    status: Literal["ok"] = "ok"
    version: str
    uptime_s: float


class DiagnoseNow(BaseModel):
    loop: str
    cause: Cause


class Counts(BaseModel):
    """Loops counted by state and by cause."""

    loops: int
    by_state: dict[str, int]
    by_cause: dict[str, int]


class AreaCounts(BaseModel):
    """One area's (or, with area "", the plant's) counts now and then, and what changed."""

    area: str = Field(description='The plant area ("" for the whole plant).')
    now: Counts
    then: Counts = Field(
        description="Each loop's latest diagnosis at that time (unknown if none yet)."
    )
    change_by_state: dict[str, int] = Field(description="Now − then, per state that changed.")
    change_by_cause: dict[str, int] = Field(description="Now − then, per cause that changed.")


class PlantSummaryOut(BaseModel):
    """The plant at a glance (`GET /plant/summary`)."""

    at: str = Field(description="Now (ISO 8601 UTC).")
    then: str = Field(description="The time compared with (ISO 8601 UTC).")
    plant: AreaCounts
    areas: list[AreaCounts]


class OscillationGroupOut(BaseModel):
    """Loops oscillating together (`GET /plant/oscillations`)."""

    period_s: float = Field(description="The common period, s (0.1 s).")
    loops: list[str] = Field(description="The member loops' ids.")
    source: str | None = Field(
        description="The likely source loop (null: none of them makes the oscillation; look "
        "upstream)."
    )
    evidence: list[str] = Field(description="Why that source, and each member's lag behind it.")
    lags_s: dict[str, float] = Field(
        {}, description="Each member's lag behind the source, s (modulo half a period)."
    )
    at: str = Field(description="When the plant-wide pass found it (ISO 8601 UTC).")


class AlertOut(BaseModel):
    """One alert delivery (`GET /alerts`)."""

    loop: str
    state: State
    cause: Cause
    rule: str = Field(description="The rule that sent it.")
    target: str = Field(description="Where it goes (an [[alerts.target]] name).")
    status: Literal["pending", "delivered", "failed"]
    attempts: int = Field(description="Delivery attempts made.")
    at: str = Field(description="When the verdict changed (ISO 8601 UTC).")
    delivered_at: str | None = None
    next_try_at: str | None = Field(None, description="When a pending alert is tried next.")
    key: str = Field(description="Its idempotency key (the webhook's Idempotency-Key).")
    last_error: str = Field("", description="Why the last attempt failed.")


class ActionEvent(BaseModel):
    """An action opened or closed in a report's period."""

    cause: Cause
    code: str
    text: str
    at: str


class LoopWeekOut(BaseModel):
    """One loop in the loop-health report."""

    loop: str
    area: str
    criticality: int | None
    state: State = Field(description="The loop's state now.")
    cause: Cause | None
    diagnoses: int = Field(description="Diagnoses in the period.")
    hours_in_state: dict[str, float] = Field(
        description="Hours of the period in each state (its span times the share of its "
        "diagnoses in that state)."
    )
    kpis: dict[str, float | None] = Field(description="Mean of each index over the period.")
    kpis_before: dict[str, float | None] = Field(
        description="The same over the period of equal length before: the trend."
    )
    opened: list[ActionEvent]
    closed: list[ActionEvent]


class HealthReport(BaseModel):
    """The loop-health report (`GET /reports/weekly`)."""

    generated_at: str
    start: str
    end: str
    loops: list[LoopWeekOut]


class MaintenanceValve(BaseModel):
    """One valve of the maintenance report."""

    loop: str
    area: str
    criticality: int | None
    cause: Cause | None
    current_S: float | None = Field(description="S now (% of travel), the trend's method.")
    limit: float = Field(description="The valve's S limit (% of travel).")
    slope_per_week: float | None
    above_limit: bool
    projected_crossing: str | None = Field(
        description="When S is projected to pass its limit (ISO 8601 UTC)."
    )
    trend_method: str | None
    op_travel_per_day: float | None = Field(description="% of span per day (latest window).")
    op_reversals_per_day: float | None
    mv_travel_per_day: float | None
    mv_reversals_per_day: float | None
    action: str | None


class MaintenanceReport(BaseModel):
    """Valves ranked by when their stiction passes its limit (`GET /reports/maintenance`)."""

    generated_at: str
    valves: list[MaintenanceValve]
