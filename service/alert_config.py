"""The ``[alerts]`` section of the configuration (issue 49 item 4): where messages go
(``[[alerts.target]]``: a webhook or an e-mail address list) and which confirmed verdict
changes send them (``[[alerts.rule]]``).

    [[alerts.target]]
    name = "ops"
    kind = "webhook"
    url = "https://ops.plant.example/hooks/plantcheck"
    secret_env = "PLANTCHECK_WEBHOOK_SECRET"   # HMAC-SHA256 of the body, optional

    [[alerts.target]]
    name = "maintenance"
    kind = "email"
    host = "smtp.plant.example"                # port 587 with STARTTLS by default
    sender = "plantcheck@plant.example"
    to = ["maintenance@plant.example"]

    [[alerts.rule]]
    name = "valves"
    targets = ["maintenance"]
    causes = ["stiction", "deadband_backlash"]
    min_criticality = 3
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Literal
from urllib.parse import urlsplit

from pydantic import BaseModel, ConfigDict, Field, SecretStr, model_validator

from plantcheck.core.names import NAME_PATTERN
from plantcheck.core.vocabulary import Cause, State
from plantcheck.service.config_secrets import read_secret


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


EMAIL = re.compile(r"^[^@\s]+@[^@\s]+$")


class AlertTarget(_Strict):
    """Where an alert goes: a webhook (JSON POST) or e-mail (SMTP)."""

    name: str = Field(pattern=NAME_PATTERN)
    kind: Literal["webhook", "email"]
    timeout_s: float = Field(10.0, gt=0, le=120)
    ca_file: str = ""
    """PEM file of the certificate authorities to trust for this target's TLS (a plant's own
    CA); empty: the system's."""
    # webhook
    url: str = ""
    secret: SecretStr = SecretStr("")
    """HMAC-SHA256 key of the ``X-Plantcheck-Signature`` header; better from ``secret_env``."""
    secret_env: str = ""
    # e-mail
    host: str = ""
    port: int = Field(587, ge=1, le=65535)
    starttls: bool = True
    """Upgrade the connection with STARTTLS before logging in (port 587); off only for a
    relay on this machine."""
    username: str = ""
    password: SecretStr = SecretStr("")
    password_env: str = ""
    sender: str = ""
    to: list[str] = []

    @model_validator(mode="after")
    def _complete(self) -> AlertTarget:
        what = f"alert target {self.name!r}"
        if self.ca_file and not Path(self.ca_file).is_file():
            raise ValueError(f"{what}: ca_file {self.ca_file!r} is not a file (a PEM bundle)")
        if self.kind == "webhook":
            parts = urlsplit(self.url)
            if parts.scheme not in ("http", "https") or not parts.hostname:
                raise ValueError(f"{what}: url must be an http(s) URL with a host, e.g. "
                                 "'https://ops.plant.example/hooks/plantcheck'")  # fmt: skip
            found = read_secret(f"{what}: secret", self.secret.get_secret_value(),
                                self.secret_env, "")  # fmt: skip
            self.secret = SecretStr(found or "")
        else:
            if not self.host:
                raise ValueError(f"{what}: an e-mail target needs host (the SMTP server)")
            if not EMAIL.match(self.sender) or not self.to:
                raise ValueError(f"{what}: an e-mail target needs sender and to (addresses)")
            bad = [a for a in self.to if not EMAIL.match(a)]
            if bad:
                raise ValueError(f"{what}: not an e-mail address: {bad[0]!r}")
            found = read_secret(f"{what}: password", self.password.get_secret_value(),
                                self.password_env, "")  # fmt: skip
            self.password = SecretStr(found or "")
        return self


class AlertRule(_Strict):
    """Which confirmed verdict changes alert whom: every filter given must hold (an empty
    list: any)."""

    name: str = Field(pattern=NAME_PATTERN)
    targets: list[str] = Field(min_length=1)
    states: list[State] = [State.fault, State.warning]
    causes: list[Cause] = []
    loops: list[str] = []
    areas: list[str] = []
    min_criticality: int = Field(1, ge=1, le=5)
    """Loops of at least this criticality (a loop without one counts as 3)."""
    quiet_period_s: float = Field(3600.0, ge=0, le=30 * 86_400)
    """After an alert of this rule for a loop, none for the same loop within this time."""


class AlertsConfig(_Strict):
    """``[alerts]``: targets and rules (none: no alerts)."""

    target: list[AlertTarget] = []
    rule: list[AlertRule] = []
    max_attempts: int = Field(10, ge=1, le=1000)
    """Tries of one delivery before it is marked failed."""
    retry_s: float = Field(30.0, gt=0, le=3600)
    """Wait before the first retry; it doubles each time, up to an hour."""

    @model_validator(mode="after")
    def _targets_exist(self) -> AlertsConfig:
        names = [t.name for t in self.target]
        if len(set(names)) != len(names):
            raise ValueError("alert target names must be unique")
        for r in self.rule:
            missing = [t for t in r.targets if t not in names]
            if missing:
                raise ValueError(
                    f"alert rule {r.name!r}: target {missing[0]!r} is not an [[alerts.target]] "
                    f"(have: {', '.join(names) or 'none'})"
                )
        return self
