"""Service configuration (contracts §4): one TOML file, ``plantcheck.toml`` by default.

Tables: ``[storage]`` (database URL, batching, retention, durable buffer), ``[api]``,
``[scheduler]``, any number of ``[[source]]`` (Modbus TCP or OPC UA endpoints) and
``[[loop]]`` (id, type, source, the tag of each of SP/PV/OP/MV/mode, scaling). Every setting
has a default where a sensible one exists; ``load_config`` refuses an invalid file with the
line, the key and what was expected (``ConfigError``).

Tag syntax:

- Modbus: ``"hr:12:float32"`` = table (``hr`` holding, ``ir`` input registers), 0-based
  address, data type (``float32``, ``float64``, ``int16``, ``uint16``, ``int32``, ``uint32``);
  word and byte order come from the source.
- OPC UA: a node id, ``"ns=2;s=FIC101.PV"``.
"""

from __future__ import annotations

import ipaddress
import re
from pathlib import Path
from typing import Literal
from urllib.parse import urlsplit

from pydantic import BaseModel, ConfigDict, Field, SecretStr, field_validator, model_validator

from plantcheck.core.names import NAME_PATTERN, NAME_RULE
from plantcheck.core.toml_config import ConfigError, dotted, load_toml, locate
from plantcheck.core.vocabulary import LoopType
from plantcheck.service.alert_config import AlertsConfig
from plantcheck.service.config_secrets import read_secret

DEFAULT_CONFIG = Path("plantcheck.toml")
SIGNAL_KEYS = ("sp", "pv", "op", "mv", "mode")
MODBUS_TAG = re.compile(r"^(hr|ir):(\d{1,5}):(float32|float64|int16|uint16|int32|uint32)$")
MODBUS_WORDS = {"int16": 1, "uint16": 1, "float32": 2, "int32": 2, "uint32": 2, "float64": 4}
OPCUA_TAG = re.compile(
    r"^((ns=\d+|nsu=[^;]+);)?"
    r"(i=\d+|s=.+|g=[0-9A-Fa-f]{8}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{12}"
    r"|b=[A-Za-z0-9+/]+={0,2})$"
)


MAX_WINDOW_S = 30 * 86400.0
"""Longest diagnosis window (s): a month of samples is far more than any method reads."""
MAX_PERIOD_S = 86400.0
"""Longest time between two diagnoses of a loop (s): a day."""


class _Strict(BaseModel):
    # inf and nan are valid TOML floats but never a valid setting
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


def is_loopback(host: str) -> bool:
    """``localhost`` or a loopback address: reachable from this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class StorageConfig(_Strict):
    """Where samples and diagnoses live; the URL decides the database."""

    url: str = "sqlite+aiosqlite:///plantcheck.db"
    """``sqlite+aiosqlite:///FILE`` (embedded default) or ``postgresql+asyncpg://USER@HOST/DB``."""
    commit_interval_s: float = Field(1.0, gt=0, le=60)
    retention_days: float = Field(30.0, ge=1, le=36500)
    """Samples older than this are deleted every hour, except each tag's newest one (the value
    a constant set point or mode reported once by OPC UA still holds)."""
    rollup_retention_days: float = Field(3650.0, ge=1, le=36500)
    """Hourly roll-ups of every signal (count, mean, lowest, highest: the long trends, read
    with ``GET /api/v1/loops/{id}/samples?resolution=hour``) are kept this long."""
    buffer_path: str = "plantcheck-buffer.db"
    """Local durable buffer used while the store is unreachable. Put it on another disk or
    volume than the database: when one disk fills or turns read-only, the other takes the
    samples (on one disk they wait in memory, at most ``memory_max_samples``)."""
    buffer_max_samples: int = Field(5_000_000, ge=1000, le=1_000_000_000)
    memory_max_samples: int = Field(500_000, ge=1000, le=50_000_000)
    """Samples held in memory while neither the database nor the durable buffer takes them
    (about 200 bytes each); past this, new samples are dropped, counted and marked as a gap."""

    @field_validator("url")
    @classmethod
    def _scheme(cls, v: str) -> str:
        if not v.startswith(("sqlite+aiosqlite://", "postgresql+asyncpg://")):
            raise ValueError(
                "expected sqlite+aiosqlite:///FILE or postgresql+asyncpg://USER@HOST:PORT/DB"
            )
        return v


class ApiConfig(_Strict):
    """The HTTP API and web page."""

    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    api_key: str = Field("", repr=False)
    """Required (header ``X-API-Key``) for every endpoint that changes anything."""
    api_key_env: str = ""
    """Environment variable holding the API key (instead of ``api_key`` in this file)."""
    api_key_file: str = ""
    """File whose first line is the API key (e.g. a systemd credential)."""
    require_key_for_reads: bool = False
    """Every request needs the key (routes, OpenAPI document, /docs, /static, the page), but
    the probes ``/healthz`` and ``/readyz``."""
    metrics: Literal["auto", "open", "key", "off"] = "auto"
    """``/metrics`` (its labels name every loop and its state): ``open``, ``key`` (the API
    key), ``off``; ``auto`` is open on a loopback ``host`` and, on an address other machines
    reach, ``key`` when a key is set, else ``off``."""
    allow_unauthenticated: bool = False
    """Serve reads without a key on an address other machines can reach (``host`` not
    loopback); refused unless written here, so an open service is a decision."""

    @model_validator(mode="after")
    def _consistent(self) -> ApiConfig:
        key = read_secret("[api] api_key", self.api_key, self.api_key_env, self.api_key_file)
        if key is not None and key != key.strip():
            # HTTP strips a header value's ends: such a key could never match
            raise ValueError(
                "api_key is blank or starts or ends with white space, which no X-API-Key "
                "header can carry: use letters, digits and punctuation"
            )
        self.api_key = key or ""
        if self.require_key_for_reads and not self.api_key:
            raise ValueError(
                "require_key_for_reads = true needs api_key: set [api] api_key (or drop "
                "require_key_for_reads)"
            )
        if self.metrics == "key" and not self.api_key:
            raise ValueError("metrics = 'key' needs api_key: set [api] api_key, or metrics = 'off'")
        if not is_loopback(self.host) and not self.api_key and not self.allow_unauthenticated:
            raise ValueError(
                f"host {self.host!r} is reachable from other machines and no api_key is set: "
                "set [api] api_key, bind host = '127.0.0.1', or write allow_unauthenticated = true"
            )
        return self

    @property
    def metrics_access(self) -> Literal["open", "key", "off"]:
        """How ``/metrics`` answers (``metrics`` with ``auto`` resolved)."""
        if self.metrics != "auto":
            return self.metrics
        if is_loopback(self.host):
            return "open"
        return "key" if self.api_key else "off"


class SchedulerConfig(_Strict):
    """Defaults of the rolling-window diagnosis (per loop overridable)."""

    window_s: float = Field(7200.0, ge=60, le=MAX_WINDOW_S)
    period_s: float = Field(600.0, ge=1, le=MAX_PERIOD_S)
    workers: int = Field(2, ge=1, le=64)
    """Worker processes that run the diagnosis chain."""
    confirm: int = Field(2, ge=1, le=100)
    """Consecutive diagnoses that must agree on a new cause before a loop's state changes."""
    quantify_every_s: float = Field(3600.0, ge=0, le=MAX_WINDOW_S)
    """Shortest time between two S/J estimates of one valve (0: every diagnosis)."""
    baseline_days: float = Field(28.0, ge=0, le=365)
    """The loop's own normal: its healthy diagnoses over this many days (0: no baseline)."""
    baseline_min: int = Field(6, ge=1, le=10_000)
    """Healthy diagnoses needed before the baseline is used."""
    engine: Literal["local", "queue"] = "local"
    """Where the diagnosis runs: ``local``, this process's worker pool (any database);
    ``queue``, jobs on the PostgreSQL job queue run by ``plantcheck worker`` processes on any
    machine (issue 28)."""
    batch_size: int = Field(100, ge=1, le=1000)
    """Loops per queued job (``engine = "queue"``)."""
    heartbeat_s: float = Field(10.0, gt=0, le=300)
    """How often a queue worker tells the database it is alive (s)."""
    stalled_after_s: float = Field(30.0, gt=0, le=3600)
    """A queue worker silent this long is dead: its jobs go to another worker (s)."""
    takeover_poll_s: float = Field(2.0, gt=0, le=60)
    """How often a standby ``plantcheck run`` tries the scheduler lock, and the holder checks
    it still holds it (s; PostgreSQL)."""
    window_cache_mb: float = Field(256.0, ge=0, le=65536)
    """Memory for the loops' rolling windows kept between diagnoses, MB (each run then reads
    only the new samples; about 0.3 MB per loop for a 2-h window at 1 s; 0: read every window
    whole)."""


class SourceConfig(_Strict):
    """A Modbus TCP device or an OPC UA server."""

    name: str = Field(pattern=NAME_PATTERN)
    protocol: Literal["modbus", "opcua"]
    host: str = "127.0.0.1"
    port: int = Field(502, ge=1, le=65535)
    device_id: int = Field(1, ge=0, le=247)
    word_order: Literal["big", "little"] = "big"
    byte_order: Literal["big", "little"] = "big"
    url: str = ""
    """OPC UA endpoint, ``opc.tcp://HOST:PORT/path``."""
    poll_interval_s: float = Field(1.0, ge=0.01, le=3600)
    """Modbus poll period, OPC UA sampling interval (s)."""
    timeout_s: float = Field(2.0, gt=0, le=60)
    mode: Literal["subscribe", "poll"] = "subscribe"
    """OPC UA: data-change subscription (default) or polling."""
    down_grace_s: float = Field(60.0, ge=0, le=86400)
    """``/readyz`` says not ready once this source has been down this long (s)."""
    security_policy: Literal["None", "Basic256Sha256"] = "None"
    """OPC UA message security; ``Basic256Sha256`` with ``security_mode``."""
    security_mode: Literal["Sign", "SignAndEncrypt"] = "SignAndEncrypt"
    certificate: str = "pki/plantcheck-client.der"
    """This client's application certificate (DER), generated self-signed on first start when
    absent: give it to the server's trusted certificates."""
    private_key: str = "pki/plantcheck-client.pem"
    """Its private key (PEM), generated with the certificate (mode 0600)."""
    server_certificate: str = ""
    """The server's certificate to pin (DER or PEM); empty: the one its endpoint offers."""
    username: str = ""
    password: SecretStr = SecretStr("")
    """Better from ``password_env`` or ``password_file`` than in this file."""
    password_env: str = ""
    """Environment variable holding the password (read at start)."""
    password_file: str = ""
    """File holding the password (first line; e.g. a systemd credential)."""
    clock: str = ""
    """Modbus: the device's clock register, POSIX seconds (``"hr:0:float64"`` on the bundled
    simulator): its value stamps the values read with it. Modbus carries no time: without it a
    value is stamped when polled, which is plant time only for a plant that runs in real time."""
    collector: str = ""
    """Read by ``plantcheck ingest --collector NAME`` on a machine at the plant, not by
    ``plantcheck run`` (empty: the service reads it)."""

    @field_validator("collector")
    @classmethod
    def _collector_name(cls, v: str) -> str:
        if v and not re.match(NAME_PATTERN, v):
            raise ValueError(f"not a collector name: use {NAME_RULE}, or leave it out")
        return v

    @model_validator(mode="after")
    def _secret(self) -> SourceConfig:
        found = read_secret(
            f"source {self.name!r}: password",
            self.password.get_secret_value(),
            self.password_env,
            self.password_file,
        )
        if found is not None:
            self.password = SecretStr(found)
        if (self.username or found is not None) and self.protocol != "opcua":
            raise ValueError(f"source {self.name!r}: username and password are OPC UA settings")
        return self

    @model_validator(mode="after")
    def _clock(self) -> SourceConfig:
        if self.clock and self.protocol != "modbus":
            raise ValueError(
                f"source {self.name!r}: clock is a Modbus setting (OPC UA carries source times)"
            )
        if self.clock and not MODBUS_TAG.match(self.clock):
            raise ValueError(
                f"source {self.name!r}: clock {self.clock!r} is not a Modbus register "
                "TABLE:ADDRESS:TYPE, e.g. 'hr:0:float64'"
            )
        return self

    @model_validator(mode="after")
    def _endpoint(self) -> SourceConfig:
        if self.protocol == "opcua":
            parts = urlsplit(self.url)
            try:
                port_ok = parts.port is None or 0 < parts.port < 65536
            except ValueError:
                port_ok = False
            if parts.scheme != "opc.tcp" or not parts.hostname or not port_ok:
                raise ValueError(
                    f"source {self.name!r}: opcua needs url = 'opc.tcp://HOST:PORT/path'"
                )
        return self


class ScaleConfig(_Strict):
    """value = raw · gain + offset, applied to one signal."""

    gain: float = 1.0
    offset: float = 0.0

    @field_validator("gain")
    @classmethod
    def _nonzero(cls, v: float) -> float:
        if v == 0:
            raise ValueError("gain 0 would make every value the offset; leave it out for 1")
        return v


class ControllerConfig(_Strict):
    """How the loop's controller takes its settings: the retuning proposal is shown in this
    form (issue 48; ``diagnosis/controller_forms.py``)."""

    form: Literal["ideal", "parallel", "series"] = "ideal"
    gain: Literal["gain", "proportional_band"] = "gain"
    integral: Literal["seconds", "minutes", "repeats_per_minute"] = "seconds"
    action: Literal["reverse", "direct"] | None = None
    pv_span: float | None = Field(None, gt=0, le=1e12)
    """PV units that make 100 % of span (the gain is then dimensionless, % per %)."""
    level_control: Literal["averaging", "tight"] = "averaging"
    """For a level loop: averaging (a surge volume passes on even flow; the proposal stays
    loose on purpose) or tight (the level itself matters: a boiler drum, a reactor)."""

    @model_validator(mode="after")
    def _band_needs_span(self) -> ControllerConfig:
        if self.gain == "proportional_band" and self.pv_span is None:
            raise ValueError(
                "gain = 'proportional_band' needs pv_span, the PV's range in engineering "
                "units (e.g. pv_span = 200.0 for 0-200 degC)"
            )
        return self


class LoopConfig(_Strict):
    """A control loop and where its signals come from."""

    id: str = Field(pattern=NAME_PATTERN)
    type: LoopType = LoopType.other
    source: str
    sp: str = ""
    pv: str
    op: str
    mv: str = ""
    mode: str = ""
    scale: dict[Literal["sp", "pv", "op", "mv"], ScaleConfig] = {}
    window_s: float | None = Field(None, ge=60, le=MAX_WINDOW_S)
    period_s: float | None = Field(None, ge=1, le=MAX_PERIOD_S)
    description: str = ""
    stiction_limit: float = Field(2.0, gt=0, le=100)
    """S (% of valve travel) at which the valve is due for maintenance (stiction report)."""
    dead_time_s: float | None = Field(None, ge=0, le=86_400)
    """The process dead time (s), for the Harris index; None: identified where a window
    shows it."""
    controller: ControllerConfig = ControllerConfig()
    """The controller's form, gain and integral units and action (the retuning's output)."""
    criticality: int | None = Field(None, ge=1, le=5)
    """How much the loop matters, 1 (little) to 5 (most): weighs its priority (3 if unset)."""
    area: str = Field("", max_length=64)
    """The plant area the loop belongs to (filters and the plant summary)."""
    unit: str = Field("", max_length=64)
    """The process unit within the area."""

    def tags(self) -> dict[str, str]:
        """Signal → tag address, for the signals this loop has."""
        return {k: getattr(self, k) for k in SIGNAL_KEYS if getattr(self, k)}


class Config(_Strict):
    """The whole service configuration."""

    storage: StorageConfig = StorageConfig()
    api: ApiConfig = ApiConfig()
    scheduler: SchedulerConfig = SchedulerConfig()
    source: list[SourceConfig] = []
    loop: list[LoopConfig] = []
    alerts: AlertsConfig = AlertsConfig()

    def collectors(self) -> list[str]:
        """The collectors named by the sources, in configuration order."""
        return list(dict.fromkeys(s.collector for s in self.source if s.collector))

    def read_by(self, collector: str) -> Config:
        """The sources ``collector`` reads ("" = the service) and the loops on them."""
        mine = [s for s in self.source if s.collector == collector]
        names = {s.name for s in mine}
        return self.model_copy(
            update={"source": mine, "loop": [lp for lp in self.loop if lp.source in names]}
        )

    def problems(self) -> list[tuple[tuple[str | int, ...], str]]:
        """Cross-references the schema cannot check: (location, what was expected)."""
        out: list[tuple[tuple[str | int, ...], str]] = []
        if self.scheduler.engine == "queue" and not self.storage.url.startswith("postgresql"):
            out.append(
                (
                    ("scheduler", "engine"),
                    "engine = 'queue' needs PostgreSQL: set [storage] url = "
                    "'postgresql+asyncpg://USER@HOST:PORT/DB' or engine = 'local'",
                )
            )
        if self.scheduler.stalled_after_s <= 2 * self.scheduler.heartbeat_s:
            out.append(
                (
                    ("scheduler", "stalled_after_s"),
                    "stalled_after_s must exceed twice heartbeat_s, or live workers would be "
                    "taken for dead",
                )
            )
        sources = {s.name: s for s in self.source}
        for i, s in enumerate(self.source):
            if sum(x.name == s.name for x in self.source) > 1:
                out.append((("source", i, "name"), f"source name {s.name!r} is used twice"))
        seen: set[str] = set()
        for i, lp in enumerate(self.loop):
            if lp.id in seen:
                out.append((("loop", i, "id"), f"loop id {lp.id!r} appears twice; make it unique"))
            seen.add(lp.id)
            src = sources.get(lp.source)
            if src is None:
                names = ", ".join(sorted(sources)) or "none defined"
                out.append(
                    (("loop", i, "source"), f"unknown source {lp.source!r} (sources: {names})")
                )
                continue
            for sig, tag in lp.tags().items():
                m = MODBUS_TAG.match(tag)
                if src.protocol == "modbus" and not m:
                    out.append(
                        (
                            ("loop", i, sig),
                            f"{tag!r} is not a Modbus tag TABLE:ADDRESS:TYPE, e.g. 'hr:12:float32'",
                        )
                    )
                elif m and int(m.group(2)) + MODBUS_WORDS[m.group(3)] > 65536:
                    out.append(
                        (
                            ("loop", i, sig),
                            f"{tag!r} reaches beyond the last Modbus register (65535): "
                            "addresses are 0-based, 0-65535",
                        )
                    )
                if src.protocol == "opcua" and not OPCUA_TAG.match(tag):
                    out.append(
                        (("loop", i, sig), f"{tag!r} is not a node id, e.g. 'ns=2;s=FIC101.PV'")
                    )
        for i, rule in enumerate(self.alerts.rule):
            unknown = [name for name in rule.loops if name not in seen]
            if unknown:
                out.append(
                    (("alerts", "rule", i, "loops"), f"unknown loop {unknown[0]!r} in the rule")
                )
        return out


def load_config(path: Path | None = None) -> Config:
    """Read and validate the configuration (``ConfigError`` with line and key when invalid)."""
    path = path or DEFAULT_CONFIG
    cfg = load_toml(path, Config)
    if not cfg.model_fields_set:
        raise ConfigError(
            str(path), None, "file", "sets nothing (empty, or only comments): describe the "
            "site's [[source]] and [[loop]] tables (README, Configuration), or leave --config "
            "out to run on the embedded defaults"
        )  # fmt: skip
    problems = cfg.problems()
    if problems:
        loc, msg = problems[0]
        text = path.read_text(encoding="utf-8")
        raise ConfigError(str(path), locate(text, loc), dotted(loc), msg)
    return cfg
