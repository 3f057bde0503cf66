"""OPC UA as plants run it (issue 28), against the simulator's real asyncua server serving only
Basic256Sha256 SignAndEncrypt with a user login and a trusted-certificates folder: the right
certificate and user get data (with ``nsu=`` node ids); an untrusted certificate and a wrong
password are refused, and the source's health says why and what to do."""

from __future__ import annotations

import asyncio
import shutil
from collections.abc import Sequence
from pathlib import Path

from simhelpers import scenario_on_free_ports, with_plant

from plantcheck.connectors.opcua import OpcUaConnector
from plantcheck.connectors.opcua_security import CLIENT_URI, OpcUaSecurity, ensure_certificate
from plantcheck.core.samples import Sample
from plantcheck.simulator.runner import PlantRunner

NS = "urn:plantcheck:simulator"


def _client(folder: Path, password: str = "s3cret") -> OpcUaSecurity:
    return OpcUaSecurity(
        certificate=folder / "cert.der",
        private_key=folder / "key.pem",
        mode="SignAndEncrypt",
        username="operator",
        password=password,
    )


async def _collect(url: str, sec: OpcUaSecurity, seconds: float) -> tuple[list[Sample], str]:
    got: list[Sample] = []

    def sink(rows: Sequence[Sample]) -> None:
        got.extend(r for r in rows if r.value is not None)

    tags = [(1, f"nsu={NS};s=FIC101.PV"), (2, f"nsu={NS};s=FIC101.OP")]
    c = OpcUaConnector("secure", sink, tags, url=url, sampling_interval_s=0.2, security=sec)
    task = asyncio.create_task(c.run())
    await asyncio.sleep(seconds)
    c.stop()
    await asyncio.wait_for(task, 15)
    return got, c.health().last_error


def test_secure_session_with_user_and_trusted_certificate(tmp_path: Path) -> None:
    trusted = tmp_path / "server" / "trusted"
    trusted.mkdir(parents=True)
    sc = scenario_on_free_ports(speed=5.0)
    sc = sc.model_copy(
        update={
            "opcua": sc.opcua.model_copy(
                update={
                    "security_policy": "Basic256Sha256",
                    "certificate": str(tmp_path / "server" / "cert.der"),
                    "private_key": str(tmp_path / "server" / "key.pem"),
                    "trusted_dir": str(trusted),
                    "username": "operator",
                    "password": "s3cret",
                }
            )
        }
    )
    good, stranger = _client(tmp_path / "plantcheck"), _client(tmp_path / "stranger")
    wrong_password = _client(tmp_path / "plantcheck", password="guess")

    async def body(runner: PlantRunner) -> None:
        # the plant's administrator trusts plantcheck's certificate, generated on first start
        assert await ensure_certificate(
            good.certificate, good.private_key, CLIENT_URI, server=False
        )
        assert good.private_key.stat().st_mode & 0o077 == 0, "the key is readable by others"
        shutil.copy(good.certificate, trusted / "plantcheck.der")
        url = sc.opcua.url

        samples, err = await _collect(url, good, 4.0)
        assert {s.tag_id for s in samples} == {1, 2}, err
        assert len(samples) > 10, err

        samples, err = await _collect(url, stranger, 3.0)
        assert samples == []
        assert "refused this client's certificate" in err, err
        assert str(stranger.certificate) in err, err  # names the file to give the server

        samples, err = await _collect(url, wrong_password, 3.0)
        assert samples == []
        assert "refused user 'operator'" in err, err

    asyncio.run(with_plant(sc, body))
