"""Simulator scenario: the plant's loops, its clock, its servers and its faults (TOML).

A scenario file (``sim.toml``) has the tables ``[clock]``, ``[modbus]``, ``[opcua]``,
``[admin]``, any number of ``[[loop]]`` and ``[[fault]]``; every key has a default except a
loop's ``id``. ``DEFAULT_SCENARIO`` is the bundled eleven-loop plant (README quick start,
end-to-end tests). Units: PV and SP in % of span inside the model, served in engineering units
through ``range``; OP and MV in % of travel; times in seconds.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from plantcheck.core.names import NAME_PATTERN
from plantcheck.core.toml_config import load_toml, parse_toml
from plantcheck.core.vocabulary import LoopType
from plantcheck.simulator.actuator import ActuatorSpec
from plantcheck.simulator.loop import FlowCharacteristic, LoopConfig, PIController, Process

SIGNALS = ("SP", "PV", "OP", "MV", "Mode")
"""Signals each loop serves, in register order."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ClockSpec(_Strict):
    """Fixed simulation step and the ratio of simulated to wall-clock time."""

    sample_time_s: float = Field(1.0, gt=0, le=60)
    speed: float = Field(1.0, gt=0, le=100_000)
    """Simulated seconds per wall-clock second (1 = real time; 100 = a day in 14.4 minutes)."""
    start: datetime | None = None
    """Simulated time of the first sample served (ISO 8601, UTC when no zone); default: now."""
    seed: int = 1
    warmup_s: float = Field(0.0, ge=0, le=7 * 86_400)
    """Simulated seconds run before the servers start: a plant has been running when it is
    first read, so its first windows hold no start-up transient (the live servers only;
    records written with ``--to-csv`` start cold)."""

    @field_validator("start")
    @classmethod
    def _utc(cls, v: datetime | None) -> datetime | None:
        if v is not None and v.tzinfo is None:
            return v.replace(tzinfo=UTC)
        return v


class ModbusSpec(_Strict):
    """Modbus TCP server: each loop's signals as float32 in holding and input registers."""

    enabled: bool = True
    host: str = "127.0.0.1"
    port: int = Field(5020, ge=0, le=65535)
    device_id: int = Field(1, ge=0, le=247)
    word_order: Literal["big", "little"] = "big"
    """``big``: high word first (ABCD); ``little``: low word first (CDAB)."""
    byte_order: Literal["big", "little"] = "big"
    """``little``: the two bytes of every register swapped (BADC, or DCBA with little words)."""


class OpcUaSpec(_Strict):
    """OPC UA server: one object per loop with variables SP, PV, OP, MV, Mode."""

    enabled: bool = True
    url: str = "opc.tcp://127.0.0.1:4840/plantcheck/"
    namespace: str = "urn:plantcheck:simulator"
    security_policy: Literal["None", "Basic256Sha256"] = "None"
    """``Basic256Sha256``: Sign and SignAndEncrypt endpoints only, with the certificate below."""
    certificate: str = "pki/simulator-server.der"
    """Server certificate (DER) and key (PEM), generated self-signed when absent."""
    private_key: str = "pki/simulator-server.pem"
    trusted_dir: str = ""
    """Folder of trusted client certificates (DER or PEM): any other client is refused with
    BadCertificateUntrusted. Empty: every client certificate is accepted."""
    username: str = ""
    """When set, the only user the server accepts (with ``password``): a test plant's login."""
    password: str = ""

    @field_validator("url")
    @classmethod
    def _scheme(cls, v: str) -> str:
        if not re.match(r"^opc\.tcp://[^/:]+(:\d+)?(/.*)?$", v):
            raise ValueError("expected opc.tcp://HOST:PORT/path")
        return v


class AdminSpec(_Strict):
    """Local admin interface (one command per line over TCP; see ``faults.py``)."""

    enabled: bool = True
    host: str = "127.0.0.1"
    port: int = Field(5021, ge=0, le=65535)


class ProcessSpec(_Strict):
    """Process from valve position to PV: ``fopdt`` (K, tau_s, theta_s, tau2_s) or
    ``integrating`` (K in %/s per % of travel, theta_s)."""

    kind: Literal["fopdt", "integrating"] = "fopdt"
    K: float = 1.0
    tau_s: float = Field(10.0, gt=0)
    theta_s: float = Field(1.0, ge=0)
    tau2_s: float = Field(0.0, ge=0)


class ControllerSpec(_Strict):
    """PI controller (Kc < 0: direct acting), output limits in %."""

    Kc: float = 1.0
    Ti_s: float = Field(10.0, gt=0)
    op_min: float = 0.0
    op_max: float = 100.0


class ValveSpec(_Strict):
    """Valve friction: ``linear`` (none), ``kano`` or ``he`` with S, J in % of travel; and
    its inherent flow characteristic."""

    model: Literal["linear", "kano", "he"] = "linear"
    S: float = Field(0.0, ge=0, le=50)
    J: float = Field(0.0, ge=0, le=50)
    characteristic: FlowCharacteristic = "linear"
    """Flow against stem position, scaled to slope 1 at ``u0`` (the tuning holds there)."""
    rangeability: float = Field(30.0, gt=1, le=200)
    """Equal-percentage rangeability R (flow ∝ R^(x/100 − 1)); ignored otherwise."""


class PositionerSpec(_Strict):
    """Positioner and its fault (simulator ``ActuatorSpec``)."""

    fault: Literal["none", "calibration", "hunting", "air_leakage", "rate_limit"] = "none"
    positioner_tau_s: float = Field(0.5, gt=0)
    bias: float = 0.0
    gain: float = Field(1.0, gt=0)
    hunting_amplitude: float = Field(0.0, ge=0)
    hunting_period_s: float = Field(5.0, gt=0)
    damping: float = Field(0.15, gt=0)
    leak_rate: float = Field(0.0, ge=0)
    rate: float = Field(1.0, gt=0)


class DisturbanceSpec(_Strict):
    """A disturbance at the process input (``load``, % of travel) or output (% of span).

    Sine (amplitude, period), random walk (std per √s), first-order filtered noise (std, tau),
    fixed steps ``[[time_s, size], ...]``, random steps (one every ``step_every_s`` on
    average, normal sizes with std ``step_std``) and another loop's cycle: ``from_loop``'s
    PV deviation from its set point (% of its span) times ``gain``, ``delay_s`` later through
    a first-order lag ``lag_s`` (a plant-wide oscillation travelling downstream).
    """

    where: Literal["load", "output"] = "load"
    sine_amplitude: float = 0.0
    sine_period_s: float = Field(100.0, gt=0)
    random_walk_std: float = Field(0.0, ge=0)
    filtered_noise_std: float = Field(0.0, ge=0)
    filtered_noise_tau_s: float = Field(20.0, gt=0)
    steps: list[tuple[float, float]] = []
    step_every_s: float = Field(0.0, ge=0)
    step_std: float = Field(0.0, ge=0)
    from_loop: str = ""
    gain: float = 1.0
    delay_s: float = Field(0.0, ge=0, le=3600)
    lag_s: float = Field(0.0, ge=0, le=3600)
    """First-order lag (s) of the path from ``from_loop`` (the process between two loops)."""


class LoopSpec(_Strict):
    """One simulated loop."""

    id: str = Field(pattern=NAME_PATTERN)
    type: LoopType = LoopType.other
    description: str = ""
    unit: str = "%"
    range: tuple[float, float] = (0.0, 100.0)
    """Engineering values of 0 % and 100 % of span (PV and SP are served in these units)."""
    process: ProcessSpec = ProcessSpec()
    controller: ControllerSpec = ControllerSpec()
    valve: ValveSpec = ValveSpec()
    positioner: PositionerSpec | None = None
    expose_mv: bool = False
    """Serve the stem position MV (smart positioner); otherwise MV is NaN."""
    noise_std: float = Field(0.0, ge=0)
    mv_noise_std: float = Field(0.0, ge=0)
    sp: float = 50.0
    u0: float = Field(50.0, ge=0, le=100)
    sp_schedule: list[tuple[float, float]] = []
    """Set-point changes ``[[time_s, sp %], ...]`` from the start of the simulation."""
    sp_repeat_s: float = Field(0.0, ge=0)
    """Repeat ``sp_schedule`` with this period (0: once)."""
    controller_schedule: list[tuple[float, float, float]] = []
    """Controller changes ``[[time_s, Kc, Ti_s], ...]``: the PI settings from that simulated
    second on (a retuning; the admin command ``tune`` does it at run time)."""
    disturbances: list[DisturbanceSpec] = []
    manual: list[tuple[float, float]] = []
    """Manual-mode intervals ``[[from_s, to_s], ...]`` (OP held, Mode = 0)."""
    cause: str = "ok"
    """The true cause (contracts §2 vocabulary), written next to exported records."""

    @field_validator("range")
    @classmethod
    def _range(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not v[1] > v[0]:
            raise ValueError("expected [low, high] with high > low")
        return v

    def to_config(self, sample_time_s: float, seed: int) -> LoopConfig:
        """The ``LoopConfig`` of this loop (disturbances are generated on line, not here)."""
        v = self.valve
        return LoopConfig(
            process=Process(**self.process.model_dump()),
            controller=PIController(**self.controller.model_dump()),
            valve=v.model,
            S=v.S,
            J=v.J,
            characteristic=v.characteristic,
            rangeability=v.rangeability,
            noise_std=self.noise_std,
            sp=self.sp,
            u0=self.u0,
            sample_time_s=sample_time_s,
            seed=seed,
            actuator=(ActuatorSpec(**self.positioner.model_dump()) if self.positioner else None),
            mv_noise_std=self.mv_noise_std,
        )

    def to_eng(self, percent: float) -> float:
        """% of span → engineering units."""
        lo, hi = self.range
        return lo + (hi - lo) * percent / 100.0


FaultKind = Literal["drop", "stall", "exception", "nan", "bad", "restart"]


class FaultSpec(_Strict):
    """A scheduled fault: at simulated second ``at_s`` for ``duration_s`` seconds.

    ``drop`` closes every client connection; ``stall`` stops answering; ``exception`` answers
    Modbus requests with exception ``code`` (4 = server device failure); ``nan`` serves NaN for
    ``loop``/``signal`` (all when empty); ``bad`` sets OPC UA status Bad (NaN over Modbus);
    ``restart`` stops the servers for ``duration_s`` and starts them again.
    """

    kind: FaultKind
    at_s: float = Field(ge=0)
    duration_s: float = Field(10.0, ge=0)
    target: Literal["modbus", "opcua", "both"] = "both"
    loop: str = ""
    signal: Literal["", "SP", "PV", "OP", "MV", "Mode"] = ""
    code: int = Field(4, ge=1, le=11)


class Scenario(_Strict):
    """A whole simulated plant."""

    name: str = "plant"
    clock: ClockSpec = ClockSpec()
    modbus: ModbusSpec = ModbusSpec()
    opcua: OpcUaSpec = OpcUaSpec()
    admin: AdminSpec = AdminSpec()
    loop: list[LoopSpec] = Field(min_length=1)
    fault: list[FaultSpec] = []

    @model_validator(mode="after")
    def _unique(self) -> Scenario:
        seen: set[str] = set()
        for spec in self.loop:
            if spec.id in seen:
                raise ValueError(f"loop id {spec.id!r} appears twice; loop ids must be unique")
            seen.add(spec.id)
        if len(self.loop) > MAX_LOOPS:
            raise ValueError(f"at most {MAX_LOOPS} loops fit the Modbus register map")
        for f in self.fault:
            if f.loop and f.loop not in seen:
                raise ValueError(f"fault names loop {f.loop!r}, which is not in the scenario")
        for spec in self.loop:
            for d in spec.disturbances:
                if d.from_loop and (d.from_loop not in seen or d.from_loop == spec.id):
                    raise ValueError(
                        f"loop {spec.id!r}: disturbance from_loop = {d.from_loop!r} must name "
                        "another loop of the scenario"
                    )
        return self


REGISTERS_PER_LOOP = 2 * len(SIGNALS)
HEADER_REGISTERS = 10
"""Registers 0–3: simulated time (float64 s since 1970, UTC); 4–5: step counter (uint32)."""
MAX_LOOPS = (65536 - HEADER_REGISTERS) // REGISTERS_PER_LOOP


DEFAULT_SCENARIO_PATH = Path(__file__).with_name("default_scenario.toml")


def load_scenario(path: Path | None = None) -> Scenario:
    """The scenario at ``path`` or the bundled default (``ConfigError`` when invalid)."""
    return load_toml(path or DEFAULT_SCENARIO_PATH, Scenario)


def parse_scenario(text: str, name: str = "<scenario>") -> Scenario:
    """Validate scenario TOML text (tests, admin)."""
    return parse_toml(text, Scenario, name)
