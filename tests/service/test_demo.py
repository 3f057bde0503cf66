"""The bundled plant end to end as a user runs it: ``plantcheck demo`` (the simulator in a new
process, OPC UA at 100x) and an integrator's Modbus simulator at 20x read through its clock
register -> ingestion -> scheduler -> store -> REST API; every loop must show its true cause."""

from __future__ import annotations

import asyncio
import re
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import pytest
from helpers import free_port
from servicehelpers import dump_dom

from plantcheck.simulator.scenario import LoopSpec, load_scenario

DEADLINE_S = 180.0
"""The README promises a minute for the demo and issue 47 three for Modbus at 20x; CI's two
loaded cores get the rest as margin."""


def _cli(*args: str, stdout: int | None = subprocess.DEVNULL) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "plantcheck.service.cli", *args],
        stdout=stdout,
        stderr=subprocess.PIPE,
    )


def _watch_true_causes(proc: subprocess.Popen[bytes], port: int) -> float:
    """Poll the loop table until every loop of the bundled plant shows its true cause (and a
    sticky valve its S): the seconds it took; fails at DEADLINE_S with what the table shows."""
    truth: dict[str, LoopSpec] = {spec.id: spec for spec in load_scenario(None).loop}
    t0 = time.monotonic()
    seen: dict[str, tuple[object, object]] = {}
    while time.monotonic() - t0 < DEADLINE_S:
        time.sleep(2)
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        try:
            loops = httpx.get(f"http://127.0.0.1:{port}/api/v1/loops", timeout=5).json()
        except httpx.TransportError:
            continue
        seen = {lp["id"]: (lp["cause"], lp["S"]) for lp in loops}
        print(f"{time.monotonic() - t0:5.0f} s {seen}", flush=True)
        if all(
            seen.get(name, (None, None))[0] == spec.cause
            and (spec.valve.S == 0 or seen[name][1] is not None)
            for name, spec in truth.items()
        ):
            page = httpx.get(f"http://127.0.0.1:{port}/", timeout=5).text
            assert all(f'data-loop="{name}"' in page for name in truth)
            print(f"every loop right after {time.monotonic() - t0:.0f} s: {seen}")
            return time.monotonic() - t0
    pytest.fail(f"after {DEADLINE_S:g} s the table shows {seen}")


def _stop(*procs: subprocess.Popen[bytes]) -> str:
    """Stop the processes; the stderr of the first."""
    err = ""
    for i, proc in enumerate(procs):
        proc.terminate()
        try:
            out = proc.communicate(timeout=30)[1]
            err = out.decode(errors="replace") if i == 0 and out else err
        except subprocess.TimeoutExpired:
            proc.kill()
    return err


@pytest.mark.slow(minutes=1.5)
def test_demo_shows_every_loop_with_its_true_cause(tmp_path: Path) -> None:
    port, admin = free_port(), free_port()
    # the test stops the demo; its duration outlasts the waits below at their limits (true
    # causes, the plant-wide group, the proposals, the retuned loops' turn to ok)
    waits = DEADLINE_S + 2 * 3 * DEMO_PERIOD_S + 4 * DIAGNOSES_TO_OK * DEMO_PERIOD_S
    proc = _cli(
        "demo", "--port", str(port), "--data-dir", str(tmp_path),
        "--admin", f"127.0.0.1:{admin}", "--duration", str(waits + 60),
    )  # fmt: skip
    try:
        _watch_true_causes(proc, port)
        _watch_plant_oscillation(port, tmp_path)
        _apply_proposals_and_watch(port, admin)
    finally:
        err = _stop(proc)
    # the demo's terminal shows plantcheck's progress, not the protocol library's notices
    assert "asyncua" not in err, err[-2000:]


DEMO_PERIOD_S = 10.0
"""The demo's diagnosis period (``plantcheck demo``'s configuration)."""


def _watch_plant_oscillation(port: int, tmp_path: Path) -> None:
    """Issue 49 item 3: within three diagnosis periods of every loop showing its cause, the
    plant-wide pass shows FIC801's cycle and the two loops it reaches as one group with FIC801
    as its source, and no other loop in any group; the plant page shows it (Chromium)."""
    t0 = time.monotonic()
    groups: list[dict[str, object]] = []
    while time.monotonic() - t0 < 3 * DEMO_PERIOD_S:
        time.sleep(1)
        groups = httpx.get(f"http://127.0.0.1:{port}/api/v1/plant/oscillations", timeout=5).json()
        if [(g["loops"], g["source"]) for g in groups] == [
            (["FIC801", "PIC803", "TIC802"], "FIC801")
        ]:
            break
    else:
        pytest.fail(f"after {3 * DEMO_PERIOD_S:g} s the plant-wide groups are {groups}")
    print(f"plant-wide group after {time.monotonic() - t0:.0f} s: {groups}")
    dom = dump_dom(f"http://127.0.0.1:{port}/plant", tmp_path / "profile")
    rows = re.findall(r'<tr class="oscillation-group" data-source="(\w*)">', dom)
    assert rows == ["FIC801"], dom[-3000:]
    assert "FIC801: its valve (cause stiction" in dom


RETUNED = ("PIC301", "TIC401")
"""The demo's aggressive and its sluggish loop (issue 48)."""

DIAGNOSES_TO_OK = 8
"""Diagnoses of each loop after the retuning within which it must read ``ok``: the first may
still judge data from before it (ingestion), TIC401's window shows its tuning only from its
next set-point step (every 30 simulated minutes, 18 s at 100x: up to two quiet windows, which
confirm nothing, ``scheduler.judges_tuning``), then two agreeing diagnoses confirm it; a
loaded machine's simulator falls behind, so more diagnoses come before that step. Counted in
diagnoses, not seconds, because a loaded machine's scheduler runs late too: with 4 CPU-bound
processes beside the test both loops read ``ok`` after 58 s and 6 diagnoses (unloaded 21 s).
That the turn comes from the retuning, not from the window moving past it, the first ``ok``'s
note says."""


def _loop(port: int, name: str) -> dict[str, Any]:
    return dict(httpx.get(f"http://127.0.0.1:{port}/api/v1/loops/{name}", timeout=5).json())


def _apply_proposals_and_watch(port: int, admin: int) -> None:
    """Issue 48: the service proposes a PI setting for the aggressive and the sluggish loop;
    typed into the simulator as the page gives it in the control system's form (the admin
    command ``tune``, the gain in % of travel per % of span), both loops read ``ok`` within
    ``DIAGNOSES_TO_OK`` diagnoses (about three periods, 30 s, unloaded): the chain judges a
    window from the retuning on (``diagnosis/controller_change.py``) and two agreeing
    diagnoses confirm it."""
    from plantcheck.simulator.faults import send_admin

    settings: dict[str, dict[str, Any]] = {}
    t0 = time.monotonic()
    while len(settings) < len(RETUNED) and time.monotonic() - t0 < 3 * DEMO_PERIOD_S:
        for name in RETUNED:
            tuning = _loop(port, name)["diagnosis"].get("tuning") or {}
            if tuning.get("dcs"):
                settings[name] = tuning
        time.sleep(1)
    assert len(settings) == len(RETUNED), {n: _loop(port, n)["diagnosis"] for n in RETUNED}
    tuned_at = time.time()
    for name, tuning in settings.items():
        dcs = tuning["dcs"]
        assert (dcs["gain_unit"], dcs["integral_unit"]) == ("% OP per % of span", "s"), dcs
        gain = dcs["gain"] if dcs["action"] == "reverse" else -dcs["gain"]
        reply = asyncio.run(send_admin("127.0.0.1", admin, f"tune {name} {gain} {dcs['integral']}"))
        assert reply.startswith("ok tune"), reply
    print(f"proposals applied: { {n: t['dcs'] for n, t in settings.items()} }")
    since: dict[str, list[dict[str, Any]]] = {}
    while time.time() - tuned_at < 4 * DIAGNOSES_TO_OK * DEMO_PERIOD_S:
        time.sleep(1)
        for name in RETUNED:
            rows = httpx.get(
                f"http://127.0.0.1:{port}/api/v1/loops/{name}/diagnoses",
                params={"limit": 10}, timeout=5,
            ).json()  # fmt: skip
            since[name] = [r for r in rows if _epoch(r["created_at"]) > tuned_at][::-1]
        causes = {name: [r["cause"] for r in rows] for name, rows in since.items()}
        if all(_loop(port, name)["cause"] == "ok" for name in RETUNED):
            break
        if any(len(rows) >= DIAGNOSES_TO_OK for rows in since.values()):
            pytest.fail(f"the loops' diagnoses since the retuning: {causes}")
    else:
        pytest.fail(f"the loops' diagnoses since the retuning: {causes}")
    print(f"both ok {time.time() - tuned_at:.0f} s after the retuning: {causes}")
    # The first `ok` is judged from the retuning on. A later one may not be: at 100x the
    # window (1 simulated hour) leaves the retuning 36 s after it, which a loaded machine's
    # late scheduler can reach before the second `ok` confirms (CI, stop 75). The service
    # may put a note first (a window shortened to the data stored so far).
    first_ok = next(r for r in since["TIC401"] if r["cause"] == "ok")
    notes = first_ok["diagnosis"]["notes"]
    assert any(n.startswith("the controller was retuned") for n in notes[:2]), notes


def _epoch(iso: str) -> float:
    return datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()


@pytest.mark.slow(minutes=2)
def test_modbus_simulator_at_20x_read_by_its_clock_shows_every_true_cause(
    tmp_path: Path,
) -> None:
    """Issue 47: Modbus carries no source time, so at 20x a poll stamped with wall time reads
    every period 20 times too short. The map the simulator exports for that speed names its
    clock register and polls once per simulated second; the service stamps each poll with the
    plant's time."""
    port, modbus = free_port(), free_port()
    sim_args = ("--modbus", f"127.0.0.1:{modbus}", "--opcua", "off", "--admin", "off")
    mapped = subprocess.run(
        [sys.executable, "-m", "plantcheck.service.cli", "simulate", *sim_args,
         "--speed", "20", "--export-map", str(tmp_path / "map.toml")],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert mapped.returncode == 0, mapped.stderr
    tables = (tmp_path / "map.toml").read_text(encoding="utf-8")
    # the plant's clock stamps the values, read twice per simulated second (25 ms at 20x)
    assert 'clock = "hr:0:float64"' in tables and "poll_interval_s = 0.025" in tables
    db = tmp_path / "plant.db"
    config = tmp_path / "plantcheck.toml"
    config.write_text(
        f'[storage]\nurl = "sqlite+aiosqlite:///{db}"\nbuffer_path = "{tmp_path / "buf.db"}"\n\n'
        f'[api]\nhost = "127.0.0.1"\nport = {port}\n\n'
        "[scheduler]\nwindow_s = 1800\nperiod_s = 10\nquantify_every_s = 60\n\n" + tables,
        encoding="utf-8",
    )
    sim = _cli("simulate", *sim_args, "--speed", "20", "--quiet")
    svc = _cli("run", "--config", str(config), "--migrate")
    try:
        _watch_true_causes(svc, port)
    finally:
        _stop(svc, sim)
