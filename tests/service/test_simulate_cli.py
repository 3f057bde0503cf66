"""``plantcheck simulate`` as a user runs it: records to CSV with their truth, the register map,
refusal of a bad scenario, and the servers started by the command itself."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest
from helpers import RunCli, free_port
from pymodbus.client import AsyncModbusTcpClient

from plantcheck.connectors.modbus_codec import decode
from plantcheck.service.cli_run import simulator_on_a_free_port


def test_to_csv_writes_records_and_truth_that_diagnose_reads(
    tmp_path: Path, run_cli: RunCli
) -> None:
    out = tmp_path / "rec"
    r = run_cli("simulate", "--to-csv", str(out), "--duration", "20m")
    assert r.returncode == 0, r.stderr
    assert "simulated 100 %" in r.stderr
    csvs = sorted(out.glob("*.csv"))
    assert len(csvs) == 11
    truth = json.loads((out / "FIC102.json").read_text())
    assert truth["cause"] == "stiction" and truth["S"] == 3.0 and truth["J"] == 1.0
    header = (out / "FIC701.csv").read_text().splitlines()[0]
    assert header == "timestamp,sp,pv,op,mv,mode"
    lines = (out / "FIC101.csv").read_text().splitlines()
    assert len(lines) == 1 + 1200
    d = run_cli("diagnose", str(out / "FIC501.csv"), "--loop-type", "flow", "--json")
    assert d.returncode == 0, d.stderr
    assert json.loads(d.stdout)["cause"] == "external_disturbance"


def test_export_map_as_toml_and_csv(tmp_path: Path, run_cli: RunCli) -> None:
    r = run_cli("simulate", "--export-map", str(tmp_path / "map.toml"))
    assert r.returncode == 0, r.stderr
    cfg = tomllib.loads((tmp_path / "map.toml").read_text())
    assert cfg["source"][0]["protocol"] == "modbus"
    assert [lp["id"] for lp in cfg["loop"]][:2] == ["FIC101", "FIC102"]
    assert cfg["loop"][0]["pv"] == "hr:12:float32"
    r = run_cli("simulate", "--export-map", str(tmp_path / "map.csv"))
    rows = (tmp_path / "map.csv").read_text().splitlines()
    assert rows[0] == "loop,signal,address,type,word_order,byte_order,unit"
    assert len(rows) == 1 + 2 + 11 * 5


def test_invalid_scenario_is_refused_with_line_and_key(tmp_path: Path, run_cli: RunCli) -> None:
    bad = tmp_path / "sim.toml"
    bad.write_text('[[loop]]\nid = "A"\nvalve = { model = "kano", S = -3 }\n')
    r = run_cli("simulate", "--config", str(bad), "--to-csv", str(tmp_path / "x"))
    assert r.returncode == 2
    assert f"{bad}:3: loop[0].valve.S: Input should be greater than or equal to 0" in r.stderr
    r = run_cli("simulate", "--to-csv", str(tmp_path / "x"), "--duration", "two hours")
    assert r.returncode == 2 and "--duration" in r.stderr
    r = run_cli("simulate", "--speed", "0", "--to-csv", str(tmp_path / "x"))
    assert r.returncode == 2 and "--speed" in r.stderr


def test_simulate_serves_until_stopped() -> None:
    port, ua_port, admin = free_port(), free_port(), free_port()
    proc = subprocess.Popen(
        [
            sys.executable, "-m", "plantcheck.service.cli", "simulate",
            "--modbus", f"127.0.0.1:{port}", "--opcua", f"opc.tcp://127.0.0.1:{ua_port}/x",
            "--admin", f"127.0.0.1:{admin}", "--speed", "50",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip

    async def read() -> float:
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2)
        for _ in range(100):
            if await client.connect():
                break
            await asyncio.sleep(0.2)
        r = await client.read_input_registers(0, count=6, device_id=1)
        client.close()
        return float(decode(r.registers[4:6], "uint32")[0])

    try:
        deadline = time.monotonic() + 30
        # the servers first show the plant after its warm-up; the clock starts once both
        # listen: the count moves from there
        first = None
        while time.monotonic() < deadline:
            steps1 = asyncio.run(read())
            if first is not None and steps1 > first:
                break
            first = steps1 if steps1 else None
            time.sleep(0.2)
        time.sleep(1.0)
        steps2 = asyncio.run(read())
        assert steps2 - steps1 >= 25  # 50x real time at 1 s per step
    finally:
        proc.terminate()
        stdout, _ = proc.communicate(timeout=20)
    assert stdout.startswith("loop,signal,address,type")  # the map is printed at start


@pytest.mark.parametrize("server", ["opcua", "modbus"])
def test_a_server_port_taken_ends_the_simulator_with_the_reason(
    run_cli: RunCli, server: str
) -> None:
    """A simulator whose OPC UA port is taken used to run on without that server, silent
    behind the library's log line, and one whose Modbus port is taken stopped with
    pymodbus' bare "Could not start listen": now the command ends with the reason and the
    fix."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", free_port()))
        taken.listen()
        port = taken.getsockname()[1]
        if server == "opcua":
            args = ("--opcua", f"opc.tcp://127.0.0.1:{port}/plantcheck/", "--modbus", "off")
        else:
            args = ("--modbus", f"127.0.0.1:{port}", "--opcua", "off")
        r = run_cli("simulate", *args, "--admin", "off", "--quiet")
    assert r.returncode == 2
    assert "cannot serve" in r.stderr and "address already in use" in r.stderr, r.stderr
    assert "choose free ports with --modbus/--opcua/--admin" in r.stderr


def test_the_demo_tries_another_port_when_its_simulators_port_is_taken() -> None:
    """The demo picks its simulator's OPC UA port; one taken before the simulator binds it
    (by any program's outgoing connection, between the pick and the bind a second later)
    makes the simulator exit, and the demo tries another."""
    with socket.socket() as taken, contextlib.ExitStack() as stack:
        # bound, not listening: as an outgoing connection's socket holds its port
        taken.bind(("127.0.0.1", free_port()))
        ports = iter([taken.getsockname()[1], free_port()])
        url = simulator_on_a_free_port(stack, "off", 100.0, choose=lambda: next(ports))
        second = int(url.split(":")[2].split("/")[0])
        assert second != taken.getsockname()[1]
        with socket.create_connection(("127.0.0.1", second), timeout=5):
            pass


def test_a_loop_whose_set_point_moves_every_20_minutes_gets_its_true_cause(
    tmp_path: Path, run_cli: RunCli
) -> None:
    """Issue 25: FIC101's operator moves its set point every 20 minutes; a 2-hour window holds
    five steps and is judged on what is left, not refused."""
    out = tmp_path / "rec"
    r = run_cli("simulate", "--to-csv", str(out), "--duration", "2h")
    assert r.returncode == 0, r.stderr
    d = run_cli("diagnose", str(out / "FIC101.csv"), "--loop-type", "flow", "--json")
    assert d.returncode == 0, d.stderr
    out_json = json.loads(d.stdout)
    assert out_json["cause"] == "ok", out_json["notes"]
    assert any("set-point step" in n for n in out_json["notes"]), out_json["notes"]
