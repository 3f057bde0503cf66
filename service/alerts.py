"""Alerts on confirmed verdict changes (issue 49 item 4): the rules that pick them, and the
dispatcher that delivers the outbox.

A loop's verdict changes only once ``confirm`` diagnoses agree (the scheduler), so an alert
reports a confirmed change. The scheduler hands each verdict the drafts its rules give
(``drafts_for``); the store keeps them with the change, quiet periods applied
(``storage.alerts``). ``AlertDispatcher`` sends what is due, on its own task: a target that
does not answer costs its time-out on that task, never ingestion's or the diagnosis's.

- **Webhook**: ``POST`` of the alert as JSON (schema ``plantcheck.alert/1``), with the headers
  ``Idempotency-Key`` (the same on every retry of one alert) and, with a secret,
  ``X-Plantcheck-Signature: sha256=<hex HMAC-SHA256 of the body>`` (as GitHub signs its
  webhooks). A 2xx answer delivers it.
- **E-mail**: SMTP with STARTTLS (default port 587), login when a username is set.

A failed attempt is tried again after ``retry_s`` (30 s), doubling up to an hour,
``max_attempts`` (10) times in all; then the alert is ``failed``, its last error kept
(``GET /api/v1/alerts``).
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import json
import logging
import smtplib
import ssl
import time
from email.message import EmailMessage
from typing import Any

import httpx

from plantcheck.service.alert_config import AlertsConfig, AlertTarget
from plantcheck.service.background import BackgroundTask
from plantcheck.service.metrics import ServiceMetrics
from plantcheck.storage.alerts import StoredAlert, alert_counts, due_alerts, mark_alert
from plantcheck.storage.store import Store

log = logging.getLogger("plantcheck.alerts")

LAST_RETRY_S = 3600.0
"""The longest wait between two attempts (s)."""


def signature(secret: str, body: bytes) -> str:
    """The ``X-Plantcheck-Signature`` header's value: ``sha256=`` and the hex HMAC."""
    return "sha256=" + hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()


def _subject(p: dict[str, Any]) -> str:
    return f"plantcheck: {p['loop']} is {p['state']} ({p['cause']})"


def _text(p: dict[str, Any]) -> str:
    lines = [
        f"Loop {p['loop']} ({p.get('description') or p.get('type') or 'loop'}) is now "
        f"{p['state']}: {p['cause']}, since {p['since']}.",
        f"Before: {p.get('previous_cause') or 'not diagnosed'}.",
        f"Action: {p.get('action') or 'none'}.",
    ]
    if p.get("area"):
        lines.append(f"Area: {p['area']}; criticality {p.get('criticality') or 3}.")
    lines.append(f"Rule {p['rule']}; alert {p['key']}.")
    return "\n".join(lines) + "\n"


def tls_context(target: AlertTarget) -> ssl.SSLContext:
    """The TLS context of a target: the system's authorities, or its ``ca_file``."""
    return ssl.create_default_context(cafile=target.ca_file or None)


def send_email(target: AlertTarget, payload: dict[str, Any]) -> None:
    """Send one alert by SMTP (blocking: run in a thread)."""
    msg = EmailMessage()
    msg["From"] = target.sender
    msg["To"] = ", ".join(target.to)
    msg["Subject"] = _subject(payload)
    msg["Message-ID"] = f"<{payload['key'].replace('/', '.')}@plantcheck>"
    msg.set_content(_text(payload))
    with smtplib.SMTP(target.host, target.port, timeout=target.timeout_s) as smtp:
        if target.starttls:
            smtp.starttls(context=tls_context(target))
        if target.username:
            smtp.login(target.username, target.password.get_secret_value())
        smtp.send_message(msg)


async def send_webhook(
    client: httpx.AsyncClient, target: AlertTarget, payload: dict[str, Any]
) -> None:
    """POST one alert; raises unless the answer is 2xx."""
    body = json.dumps(payload, separators=(",", ":"), sort_keys=True).encode()
    headers = {"Content-Type": "application/json", "Idempotency-Key": str(payload["key"])}
    secret = target.secret.get_secret_value()
    if secret:
        headers["X-Plantcheck-Signature"] = signature(secret, body)
    r = await client.post(target.url, content=body, headers=headers, timeout=target.timeout_s)
    if not r.is_success:
        raise RuntimeError(f"HTTP {r.status_code}: {r.text[:200]}")


class AlertDispatcher(BackgroundTask):
    """Delivers the outbox every ``poll_s``, one alert at a time."""

    name = "alert-dispatcher"

    def __init__(
        self,
        store: Store,
        cfg: AlertsConfig,
        metrics: ServiceMetrics,
        poll_s: float = 2.0,
    ) -> None:
        self.store = store
        self.cfg = cfg
        self.metrics = metrics
        self.poll_s = poll_s
        self.targets = {t.name: t for t in cfg.target}
        self._failing: set[str] = set()
        """Targets whose last attempt failed (logged once until one succeeds)."""

    async def _run(self) -> None:
        clients = {
            t.name: httpx.AsyncClient(verify=tls_context(t))
            for t in self.targets.values()
            if t.kind == "webhook"
        }
        try:
            while True:
                try:
                    await self.deliver_due(clients)
                except Exception as exc:  # the store is down: the outbox waits for it
                    log.debug("alert outbox not read: %s", exc)
                await asyncio.sleep(self.poll_s)
        finally:
            for c in clients.values():
                await c.aclose()

    async def deliver_due(self, clients: dict[str, httpx.AsyncClient]) -> int:
        """Attempt every due alert once (``clients``: each webhook target's); returns how
        many were delivered."""
        delivered = 0
        for alert in await due_alerts(self.store, time.time_ns() // 1000):
            delivered += await self._attempt(clients.get(alert.target), alert)
        counts = await alert_counts(self.store)
        self.metrics.alerts_pending.set(counts["pending"])
        return delivered

    async def _attempt(self, client: httpx.AsyncClient | None, alert: StoredAlert) -> int:
        target = self.targets.get(alert.target)
        attempts = alert.attempts + 1
        try:
            if target is None:
                raise LookupError(f"target {alert.target!r} is no longer configured")
            if target.kind == "webhook":
                assert client is not None
                await send_webhook(client, target, alert.payload)
            else:
                await asyncio.to_thread(send_email, target, alert.payload)
        except Exception as exc:
            error = f"{type(exc).__name__}: {exc}"
            if attempts >= self.cfg.max_attempts or target is None:
                await mark_alert(self.store, alert.id, "failed", attempts, error=error)
                self.metrics.alerts.labels("failed").inc()
                log.error("alert %s to %s failed for good: %s", alert.key, alert.target, error)
            else:
                wait = min(self.cfg.retry_s * 2 ** (attempts - 1), LAST_RETRY_S)
                due = time.time_ns() // 1000 + int(wait * 1e6)
                await mark_alert(self.store, alert.id, "pending", attempts, next_try_us=due,
                                 error=error)  # fmt: skip
                self.metrics.alerts.labels("retried").inc()
                if alert.target not in self._failing:
                    log.warning("alert target %s: %s (retrying; logged once)", alert.target, error)
            self._failing.add(alert.target)
            return 0
        await mark_alert(self.store, alert.id, "delivered", attempts,
                         delivered_us=time.time_ns() // 1000)  # fmt: skip
        self.metrics.alerts.labels("delivered").inc()
        if alert.target in self._failing:
            self._failing.discard(alert.target)
            log.info("alert target %s: delivering again", alert.target)
        return 1
