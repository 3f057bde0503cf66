"""Alerts on confirmed verdict changes (issue 49 item 4), with real parts: a ``plantcheck run``
process over a SQLite file, a webhook receiver and an SMTP server with STARTTLS (aiosmtpd) on
127.0.0.1. The service alerts a sticky valve's fault by webhook and e-mail; the webhook's
receiver is down at first, the service is killed (SIGKILL) with the alert still in its outbox
and started again: the alert is delivered once, signed, with its idempotency key, and the
e-mail once, over TLS. The rules' filters and the quiet period are checked on their own."""

from __future__ import annotations

import asyncio
import datetime as dt
import hashlib
import hmac
import ipaddress
import json
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import httpx
import pytest
from aiosmtpd.controller import Controller
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID
from helpers import free_port, verdict_of
from servicehelpers import CLI, record_start, start_service

from plantcheck.service.alert_config import AlertRule
from plantcheck.service.alert_rules import drafts_for, rules_for_loop
from plantcheck.simulator.export import write_records
from plantcheck.simulator.scenario import load_scenario
from plantcheck.storage.alerts import list_alerts
from plantcheck.storage.database import upgrade
from plantcheck.storage.results import PendingVerdict, record_verdicts
from plantcheck.storage.store import Store

SECRET = "hook-secret"


def _self_signed(folder: Path) -> tuple[Path, Path]:
    """A certificate for 127.0.0.1 and its key (PEM files)."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")])
    now = dt.datetime.now(dt.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=1))
        .add_extension(
            x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
            critical=False,
        )
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(key, hashes.SHA256())
    )
    cert_pem, key_pem = folder / "smtp.pem", folder / "smtp.key"
    cert_pem.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_pem.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return cert_pem, key_pem


class Mailbox:
    """aiosmtpd handler: keeps every message (and whether the session was under TLS)."""

    def __init__(self) -> None:
        self.messages: list[tuple[bool, bytes]] = []

    async def handle_DATA(self, server: Any, session: Any, envelope: Any) -> str:
        self.messages.append((session.ssl is not None, envelope.content))
        return "250 OK"


@contextmanager
def smtp_server(folder: Path, port: int) -> Iterator[Mailbox]:
    import ssl

    cert, key = _self_signed(folder)
    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ctx.load_cert_chain(cert, key)
    box = Mailbox()
    ctl = Controller(box, hostname="127.0.0.1", port=port, tls_context=ctx, require_starttls=True)
    ctl.start()
    try:
        yield box
    finally:
        ctl.stop()


@contextmanager
def webhook_receiver(port: int) -> Iterator[list[tuple[dict[str, str], bytes]]]:
    got: list[tuple[dict[str, str], bytes]] = []

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            body = self.rfile.read(int(self.headers["Content-Length"]))
            got.append(({k.lower(): v for k, v in self.headers.items()}, body))
            self.send_response(204)
            self.end_headers()

        def log_message(self, *args: object) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield got
    finally:
        server.shutdown()
        server.server_close()


def _config(folder: Path, api: int, hook: int, smtp: int, ca: Path) -> Path:
    text = f"""
[storage]
url = "sqlite+aiosqlite:///{folder / "plant.db"}"
buffer_path = "{folder / "buffer.db"}"

[api]
port = {api}

[scheduler]
window_s = 1800
period_s = 2
workers = 1
confirm = 1

[[source]]
name = "ua"
protocol = "opcua"
url = "opc.tcp://127.0.0.1:{free_port()}/none/"

[[loop]]
id = "FIC102"
type = "flow"
source = "ua"
area = "north"
criticality = 4
sp = "ns=2;s=FIC102.SP"
pv = "ns=2;s=FIC102.PV"
op = "ns=2;s=FIC102.OP"

[alerts]
retry_s = 0.5

[[alerts.target]]
name = "ops"
kind = "webhook"
url = "http://127.0.0.1:{hook}/hook"
secret = "{SECRET}"
timeout_s = 2

[[alerts.target]]
name = "maintenance"
kind = "email"
host = "127.0.0.1"
port = {smtp}
ca_file = "{ca}"
sender = "plantcheck@plant.example"
to = ["maintenance@plant.example"]

[[alerts.rule]]
name = "valves"
targets = ["ops", "maintenance"]
causes = ["stiction"]
areas = ["north"]
min_criticality = 3
"""
    path = folder / "plantcheck.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _alerts(url: str) -> list[dict[str, Any]]:
    return list(httpx.get(f"{url}/api/v1/alerts", timeout=5).json())


def _until(what: str, check: Any, timeout_s: float = 120.0) -> Any:
    deadline = time.monotonic() + timeout_s
    last = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(0.5)
    raise AssertionError(f"{what}: not within {timeout_s:g} s ({last!r})")


@pytest.mark.slow
def test_a_confirmed_fault_is_alerted_once_by_webhook_and_email_across_a_kill(
    tmp_path: Path,
) -> None:
    api, hook, smtp = free_port(), free_port(), free_port()
    records = tmp_path / "records"
    write_records(load_scenario(None), records, 1800.0, record_start(1800.0))
    with smtp_server(tmp_path, smtp) as mailbox:
        config = _config(tmp_path, api, hook, smtp, tmp_path / "smtp.pem")
        subprocess.run([*CLI, "db", "upgrade", "--config", str(config)], check=True,
                       capture_output=True)  # fmt: skip
        subprocess.run([*CLI, "import", str(records / "FIC102.csv"), "--loop", "FIC102",
                        "--loop-type", "flow", "--config", str(config)],
                       check=True, capture_output=True)  # fmt: skip
        svc = start_service(config, api, {}, record_start())
        try:
            # the e-mail goes out; the webhook's receiver is down, so its alert waits
            _until("the e-mail", lambda: mailbox.messages)
            pending = _until(
                "a failed webhook attempt",
                lambda: [a for a in _alerts(svc.url) if a["target"] == "ops" and a["attempts"]],
            )
            assert pending[0]["status"] == "pending" and pending[0]["last_error"], pending
        finally:
            svc.proc.send_signal(signal.SIGKILL)
            svc.proc.wait(10)
        with webhook_receiver(hook) as posts:
            svc = start_service(config, api, {}, record_start())
            try:
                _until("the webhook", lambda: posts)
                time.sleep(3.0)  # a second delivery, were there one, would come by now
                alerts = _alerts(svc.url)
                metrics = httpx.get(f"{svc.url}/metrics", timeout=5).text
            finally:
                svc.stop()
    assert len(posts) == 1 and len(mailbox.messages) == 1, (posts, mailbox.messages)
    by_target = {a["target"]: a for a in alerts}
    assert set(by_target) == {"ops", "maintenance"} and len(alerts) == 2, alerts
    assert all(a["status"] == "delivered" for a in alerts), alerts
    assert by_target["ops"]["attempts"] >= 2 and by_target["maintenance"]["attempts"] == 1
    headers, body = posts[0]
    payload = json.loads(body)
    assert payload["schema"] == "plantcheck.alert/1"
    assert (payload["loop"], payload["state"], payload["cause"]) == ("FIC102", "fault", "stiction")
    assert payload["area"] == "north" and payload["criticality"] == 4 and payload["action"]
    assert headers["idempotency-key"] == by_target["ops"]["key"] == payload["key"]
    mac = hmac.new(SECRET.encode(), body, hashlib.sha256).hexdigest()
    assert headers["x-plantcheck-signature"] == f"sha256={mac}"
    tls, mail = mailbox.messages[0]
    assert tls and b"Subject: plantcheck: FIC102 is fault (stiction)" in mail
    assert 'plantcheck_alerts_total{status="delivered"}' in metrics


def test_rules_filter_by_loop_area_criticality_state_and_cause() -> None:
    rules = [
        AlertRule(name="faults", targets=["a"]),
        AlertRule(name="north-valves", targets=["a", "b"], causes=["stiction"], areas=["north"]),
        AlertRule(name="critical", targets=["b"], min_criticality=4, states=["fault", "ok"]),
        AlertRule(name="one", targets=["a"], loops=["TIC1"]),
    ]
    north = rules_for_loop(rules, "FIC1", "north", None)  # criticality 3 when unset
    assert [r.name for r in north] == ["faults", "north-valves"]
    facts = {"loop": "FIC1", "state": "fault", "cause": "stiction"}
    drafts = drafts_for(north, facts)
    assert [(d.rule, d.target) for d in drafts] == [
        ("faults", "a"), ("north-valves", "a"), ("north-valves", "b"),
    ]  # fmt: skip
    sluggish = drafts_for(north, {**facts, "state": "warning", "cause": "sluggish_tuning"})
    assert [d.rule for d in sluggish] == ["faults"]
    assert [d.rule for d in drafts_for(north, {**facts, "state": "ok", "cause": "ok"})] == []
    critical = rules_for_loop(rules, "TIC1", "", 5)
    assert [r.name for r in critical] == ["faults", "critical", "one"]
    back = drafts_for(critical, {"loop": "TIC1", "state": "ok", "cause": "ok"})
    assert [d.rule for d in back] == ["critical"]  # a rule may ask for recoveries too


def test_an_alert_is_stored_with_its_change_and_the_quiet_period_holds(tmp_path: Path) -> None:
    """The outbox row comes in the verdict change's transaction (none for a diagnosis that
    changes nothing), and a rule alerts a loop again only after its quiet period."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'store.db'}"
    upgrade(url)
    rule = rules_for_loop([AlertRule(name="r", targets=["a"], quiet_period_s=600)], "L1", "", 3)
    minute = 60_000_000

    async def run() -> list[tuple[str, int]]:
        store = await Store.open(url)
        try:
            row = await store.ensure_loop("L1", signals=("pv", "op"))
            t0 = 10**15
            for k, cause in enumerate(["stiction", "stiction", "ok", "stiction", "ok"] * 3):
                v = verdict_of(row, t0 + k * minute, cause)
                facts = {"loop": "L1", "state": v.state, "cause": cause}
                await record_verdicts(
                    store, [PendingVerdict(v, True, None, drafts_for(rule, facts))]
                )
            _, rows = await list_alerts(store)
            return [(a.cause, (a.created_us - t0) // minute) for a in reversed(rows)]
        finally:
            await store.close()

    # changes to stiction at minutes 0, 3, 5, 8, 10, 13: alerted at 0 and 10 (600 s quiet)
    assert asyncio.run(run()) == [("stiction", 0), ("stiction", 10)]
