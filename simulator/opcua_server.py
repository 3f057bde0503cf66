"""OPC UA server of the simulated plant (asyncua 2.1).

Address space: one object per loop under ``Objects`` with node id ``ns=<idx>;s=<loop id>`` and
browse name ``<idx>:<loop id>``; its variables ``SP``, ``PV``, ``OP``, ``Mode`` (and ``MV`` when
the loop exposes its stem position) have node ids ``ns=<idx>;s=<loop id>.<signal>``, type
Double, read-only, and the properties ``EngineeringUnits`` (EUInformation) and ``EURange``.
``<idx>`` is the index of the namespace ``urn:plantcheck:simulator`` (2 on a fresh server).
Every value carries the *simulated* sample time as its source timestamp and a status code
(Good, or Bad during a ``bad`` fault). Security: none (loopback use by default).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.permission_rules import User, UserRole
from cryptography import x509
from cryptography.hazmat.primitives import serialization

from plantcheck.connectors.opcua_security import ensure_certificate
from plantcheck.simulator.faults import FaultState
from plantcheck.simulator.plant import Plant
from plantcheck.simulator.scenario import SIGNALS, OpcUaSpec, Scenario

BAD = ua.StatusCode(ua.StatusCodes.BadSensorFailure)
GOOD = ua.StatusCode(ua.StatusCodes.Good)
_UNECE_CODES = {"%": 20529, "m3/h": 5125448, "t/h": 4534354, "bar": 4342098, "degC": 4408652}


def node_id(namespace_index: int, loop_id: str, signal: str | None = None) -> ua.NodeId:
    """Node id of a loop object (``signal`` None) or of one of its variables."""
    ident = loop_id if signal is None else f"{loop_id}.{signal}"
    return ua.NodeId(ident, namespace_index)


def _eu(unit: str) -> ua.EUInformation:
    return ua.EUInformation(
        NamespaceUri="http://www.opcfoundation.org/UA/units/un/cefact",
        UnitId=_UNECE_CODES.get(unit, -1),
        DisplayName=ua.LocalizedText(unit),
        Description=ua.LocalizedText(unit),
    )


SERVER_URI = "urn:plantcheck:simulator:server"


class OneUser:
    """A user manager that knows one user name and password (a test plant's login)."""

    def __init__(self, username: str, password: str) -> None:
        self.username, self.password = username, password

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> User | None:
        if username == self.username and password == self.password:
            return User(role=UserRole.User, name=username)
        return None


def trusted_only(folder: Path) -> Callable[[x509.Certificate, Any], Awaitable[None]]:
    """A certificate check that accepts the client certificates found in ``folder`` (read at
    each connection, so a certificate copied there is trusted at once) and refuses others."""

    async def validate(cert: x509.Certificate, app_description: Any) -> None:
        der = cert.public_bytes(serialization.Encoding.DER)
        for f in sorted(folder.glob("*")):
            data = f.read_bytes()
            known = x509.load_pem_x509_certificate(data) if data.startswith(b"-----") else None
            if der == data or (known is not None and known == cert):
                return
        raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)

    return validate


async def _secure(server: Server, spec: OpcUaSpec) -> None:
    """Basic256Sha256 endpoints (Sign, SignAndEncrypt) with the server's certificate."""
    server.set_security_policy(
        [
            ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
            ua.SecurityPolicyType.Basic256Sha256_Sign,
        ]
    )
    await server.set_application_uri(SERVER_URI)
    cert, key = Path(spec.certificate), Path(spec.private_key)
    await ensure_certificate(cert, key, SERVER_URI, server=True)
    await server.load_certificate(str(cert))
    await server.load_private_key(str(key))
    if spec.trusted_dir:
        server.set_certificate_validator(trusted_only(Path(spec.trusted_dir)))


class OpcUaPlantServer:
    """Serves a ``Plant`` over OPC UA; ``publish`` writes the latest sample of every loop."""

    def __init__(self, spec: OpcUaSpec, scenario: Scenario, faults: FaultState) -> None:
        self.spec = spec
        self.scenario = scenario
        self.faults = faults
        self.server: Server | None = None
        self.namespace_index = 0
        self._nodes: list[list[ua.NodeId | None]] = []

    async def start(self) -> None:
        # asyncua's INFO is a line per publish; never lower what the command asked for
        lib = logging.getLogger("asyncua")
        lib.setLevel(max(lib.getEffectiveLevel(), logging.WARNING))
        spec = self.spec
        users = OneUser(spec.username, spec.password) if spec.username else None
        server = Server(user_manager=users)
        await server.init()
        server.set_endpoint(spec.url)
        server.set_server_name("plantcheck simulator")
        if spec.security_policy == "Basic256Sha256":
            await _secure(server, spec)
        else:
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        if users is not None:
            server.set_identity_tokens([ua.UserNameIdentityToken])
        idx = await server.register_namespace(self.spec.namespace)
        self.namespace_index = idx
        objects = server.nodes.objects
        self._nodes = []
        for lp in self.scenario.loop:
            obj = await objects.add_object(node_id(idx, lp.id), f"{idx}:{lp.id}")
            row: list[ua.NodeId | None] = []
            for sig in SIGNALS:
                if sig == "MV" and not lp.expose_mv:
                    row.append(None)
                    continue
                var = await obj.add_variable(
                    node_id(idx, lp.id, sig), f"{idx}:{sig}", 0.0, ua.VariantType.Double
                )
                unit = lp.unit if sig in ("SP", "PV") else ("%" if sig != "Mode" else "")
                if unit:
                    lo, hi = lp.range if sig in ("SP", "PV") else (0.0, 100.0)
                    await var.add_property(idx, "EngineeringUnits", _eu(unit))
                    await var.add_property(idx, "EURange", ua.Range(Low=lo, High=hi))
                row.append(var.nodeid)
            self._nodes.append(row)
        await server.start()
        self.server = server

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.stop()
            self.server = None

    def _transports(self) -> list[object]:
        if self.server is None:
            return []
        return list(self.server.iserver.asyncio_transports)

    def drop_connections(self) -> None:
        """Close every client connection (clients see the connection reset)."""
        for t in self._transports():
            t.close()  # type: ignore[attr-defined]

    def set_stalled(self, stalled: bool) -> None:
        """Stop (or resume) reading from every open connection: requests go unanswered."""
        for t in self._transports():
            (t.pause_reading if stalled else t.resume_reading)()  # type: ignore[attr-defined]

    async def publish(self, plant: Plant) -> None:
        """Write every loop's latest sample with its simulated source timestamp."""
        if self.server is None:
            return
        stamp = plant.time
        now = datetime.now(UTC)
        for i, spec in enumerate(self.scenario.loop):
            for j, sig in enumerate(SIGNALS):
                nid = self._nodes[i][j]
                if nid is None:
                    continue
                value = float(plant.values[i, j])
                status = GOOD
                if self.faults.masked("bad", "opcua", spec.id, sig):
                    status = BAD
                elif self.faults.masked("nan", "opcua", spec.id, sig):
                    value = math.nan
                dv = ua.DataValue(
                    Value=ua.Variant(value, ua.VariantType.Double),
                    StatusCode=status,
                    SourceTimestamp=stamp,
                    ServerTimestamp=now,
                )
                await self.server.write_attribute_value(nid, dv)
