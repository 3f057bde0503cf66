"""OPC UA security as plants run it (OPC UA Part 2 and 4; asyncua 2.1): the Basic256Sha256
policy with Sign or SignAndEncrypt, an application instance certificate, and a user name.

The client's certificate (DER) and private key (PEM, mode 0600) are generated self-signed on
first start when absent, for the application URI ``CLIENT_URI``; the server's administrator
then copies the certificate into the server's trusted folder (most servers put a refused
certificate in a "rejected" folder to move). Without a pinned ``server_certificate`` the server
certificate is the one its endpoint offers (trust on first use). A refusal is explained
(``explain_refusal``) rather than passed on as a bare status code.
"""

from __future__ import annotations

import logging
import os
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

log = logging.getLogger("plantcheck.connectors")

CLIENT_URI = "urn:plantcheck:client"
"""Application URI of plantcheck's OPC UA client (in its certificate's subject alt. name)."""


@dataclass(frozen=True)
class OpcUaSecurity:
    """How one source's sessions are secured (``[[source]]`` keys of the same names)."""

    certificate: Path
    private_key: Path
    mode: str = "SignAndEncrypt"
    """``Sign`` or ``SignAndEncrypt``."""
    server_certificate: Path | None = None
    username: str = ""
    password: str = field(default="", repr=False)


async def ensure_certificate(cert: Path, key: Path, app_uri: str, *, server: bool) -> bool:
    """Make a self-signed certificate (DER, one year) and its key (PEM) when either is
    missing; True when they were made."""
    if cert.is_file() and key.is_file():
        return False
    cert.parent.mkdir(parents=True, exist_ok=True)
    key.parent.mkdir(parents=True, exist_ok=True)
    use = ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH
    await setup_self_signed_certificate(
        key,
        cert,
        app_uri,
        socket.gethostname(),
        [use],
        {
            "commonName": "plantcheck server" if server else "plantcheck",
            "organizationName": "plantcheck",
        },
    )
    os.chmod(key, 0o600)
    return True


async def secure(client: Client, sec: OpcUaSecurity, source: str) -> None:
    """Set the policy, certificate and user of ``client`` (before ``connect``)."""
    client.application_uri = CLIENT_URI
    if await ensure_certificate(sec.certificate, sec.private_key, CLIENT_URI, server=False):
        log.warning(
            "%s: generated the application certificate %s (key %s): add it to the OPC UA "
            "server's trusted certificates",
            source,
            sec.certificate,
            sec.private_key,
        )
    mode = (
        ua.MessageSecurityMode.Sign if sec.mode == "Sign" else ua.MessageSecurityMode.SignAndEncrypt
    )
    await client.set_security(
        SecurityPolicyBasic256Sha256,
        str(sec.certificate),
        str(sec.private_key),
        server_certificate=str(sec.server_certificate) if sec.server_certificate else None,
        mode=mode,
    )
    if sec.username:
        client.set_user(sec.username)
        client.set_password(sec.password)


_CERTIFICATE_REFUSED = frozenset(
    {
        "BadSecurityChecksFailed",
        "BadCertificateUntrusted",
        "BadCertificateInvalid",
        "BadCertificateUriInvalid",
        "BadCertificateTimeInvalid",
        "BadCertificateRevoked",
        "BadCertificateUseNotAllowed",
    }
)
_USER_REFUSED = frozenset(
    {"BadUserAccessDenied", "BadIdentityTokenRejected", "BadIdentityTokenInvalid"}
)


def _status_name(exc: BaseException) -> str:
    code: Any = getattr(exc, "code", None)
    if code is not None:
        with_name = ua.StatusCode(code)
        return str(with_name.name)
    return type(exc).__name__


def explain_refusal(exc: BaseException, sec: OpcUaSecurity) -> str | None:
    """What to do about a refused secure connection, or None when ``exc`` is no refusal."""
    name = _status_name(exc)
    if name in _CERTIFICATE_REFUSED:
        return (
            f"the server refused this client's certificate ({name}): add {sec.certificate} to "
            "the server's trusted certificates (or check that it has not expired)"
        )
    if name in _USER_REFUSED:
        return f"the server refused user {sec.username!r} ({name}): check username and password"
    text = str(exc)
    if "No matching endpoints" in text or "no endpoint" in text.lower():
        return (
            f"the server offers no Basic256Sha256 {sec.mode} endpoint: set security_mode to one "
            "it offers, or security_policy = 'None' where the plant allows it"
        )
    return None
