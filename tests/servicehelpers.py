"""A real ``plantcheck run`` process over a SQLite store filled with simulated loop records."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from helpers import free_port

from plantcheck.simulator.export import map_toml, write_records
from plantcheck.simulator.scenario import load_scenario

CLI = [sys.executable, "-m", "plantcheck.service.cli"]
API_KEY = "test-key-123"


@dataclass
class Service:
    """A running service: its base URL, process, configuration file and the loops' truth."""

    url: str
    proc: subprocess.Popen[bytes]
    config: Path
    truth: dict[str, dict[str, object]]
    start: datetime

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def write_config(
    folder: Path,
    *,
    port: int,
    reads_need_key: bool = False,
    down_grace_s: float = 86400.0,
    period_s: float = 3.0,
) -> Path:
    """Configuration: SQLite in ``folder``, the default plant's loops on an OPC UA source
    nobody serves (the records were imported; the source stays down, and ``/readyz`` says
    ready until it has been down ``down_grace_s``), 1-hour windows diagnosed every ``period_s``, a
    sticky valve's S estimated once (the scheduler's default ``quantify_every_s``: the
    records do not change; estimated on every diagnosis, one service took 1.6 of this
    machine's two cores for as long as it ran, and two lived through most of a test run)."""
    sc = load_scenario(None)
    sc = sc.model_copy(
        update={
            "opcua": sc.opcua.model_copy(update={"url": f"opc.tcp://127.0.0.1:{free_port()}/none/"})
        }
    )
    text = "\n".join(
        [
            "[storage]",
            f'url = "sqlite+aiosqlite:///{folder / "plant.db"}"',
            f'buffer_path = "{folder / "buffer.db"}"',
            "[api]",
            f"port = {port}",
            f'api_key = "{API_KEY}"',
            f"require_key_for_reads = {'true' if reads_need_key else 'false'}",
            "[scheduler]",
            "window_s = 3600",
            f"period_s = {period_s:g}",
            "workers = 2",
            "confirm = 1",
            "",
            map_toml(sc, protocol="opcua").replace(
                'protocol = "opcua"\n', f'protocol = "opcua"\ndown_grace_s = {down_grace_s}\n', 1
            ),
        ]
    )
    path = folder / f"plantcheck-{port}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def record_start(duration_s: float = 3600.0) -> datetime:
    """Where the imported records start: so that they end about now, as live data would
    (older data is outside the rolling window, or even the retention)."""
    now = datetime.now(UTC).replace(second=0, microsecond=0)
    return now - timedelta(seconds=duration_s)


def fill_store(
    folder: Path, config: Path, duration_s: float = 3600.0
) -> tuple[datetime, dict[str, dict[str, object]]]:
    """Simulate the default plant, ``plantcheck db upgrade`` and ``plantcheck import`` every
    loop's record; returns where the records start and the truth per loop.

    The commands run in this process (typer's runner, the commands' own code): as twelve new
    processes they took 20 s here, in this one 5 (``tests/storage/test_store.py`` runs
    ``import`` in a new process, as a user does)."""
    from typer.testing import CliRunner

    from plantcheck.service.cli import app

    sc = load_scenario(None)
    start = record_start(duration_s)
    records = folder / "records"
    write_records(sc, records, duration_s, start)
    runner = CliRunner()

    def run(*args: str) -> None:
        done = runner.invoke(app, [*args, "--config", str(config)])
        assert done.exit_code == 0, (args, done.output)

    run("db", "upgrade")
    truth: dict[str, dict[str, object]] = {}
    for spec in sc.loop:
        truth[spec.id] = json.loads((records / f"{spec.id}.json").read_text())
        run("import", str(records / f"{spec.id}.csv"), "--loop", spec.id, "--loop-type", spec.type)
    return start, truth


def start_service(
    config: Path, port: int, truth: dict[str, dict[str, object]], start: datetime
) -> Service:
    """``plantcheck run --config`` in a new process; returns once /readyz answers 200."""
    log = config.with_suffix(".log")
    with log.open("wb") as err:
        proc = subprocess.Popen([*CLI, "run", "--config", str(config)], stderr=err)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            tail = log.read_text(errors="replace")[-3000:]
            raise RuntimeError(f"plantcheck run exited with {proc.returncode}:\n{tail}")
        try:
            if httpx.get(f"{url}/readyz", timeout=2).status_code == 200:
                return Service(url, proc, config, truth, start)
        except httpx.TransportError:
            pass
        time.sleep(0.3)
    proc.kill()
    raise RuntimeError("plantcheck run did not become ready within 60 s")


def wait_diagnosed(
    url: str,
    n: int,
    timeout_s: float = 120.0,
    headers: dict[str, str] | None = None,
    sticky: frozenset[str] = frozenset(),
) -> list[dict[str, object]]:
    """Poll GET /api/v1/loops until ``n`` loops have a cause and the ``sticky`` ones an S
    (estimated once a second window confirms stiction)."""
    deadline = time.monotonic() + timeout_s
    loops: list[dict[str, object]] = []
    while time.monotonic() < deadline:
        loops = httpx.get(f"{url}/api/v1/loops", headers=headers, timeout=10).json()
        with_s = {lp["id"] for lp in loops if lp["S"] is not None}
        if sum(lp["cause"] is not None for lp in loops) >= n and sticky <= with_s:
            return loops
        time.sleep(1)
    raise AssertionError(
        f"only {sum(lp['cause'] is not None for lp in loops)} of {n} diagnosed, "
        f"S of {sorted(sticky - {lp['id'] for lp in loops if lp['S'] is not None})} missing"
    )


class SharedService:
    """The session's running service over 1 h of the default plant (11 loops, every loop
    diagnosed): built by the first test that asks for it, stopped once a test is followed by
    one that does not use it (``stop_unless_needed``), built again if a later test does.

    A session fixture would live to the end of the run: the tests that use it run together,
    first on their worker, and after them the service went on diagnosing for the other 90 %
    of the run, beside every other test (a tenth of a core)."""

    def __init__(self) -> None:
        self._running: Service | None = None
        self._folder: tempfile.TemporaryDirectory[str] | None = None
        self._failed: str | None = None

    def get(self) -> Service:
        """The running service; a build that failed fails every test of the row that asks
        again, with the first failure's message, as a session fixture's error would."""
        if self._failed is not None:
            raise RuntimeError(f"the shared service could not be built: {self._failed}")
        if self._running is None:
            try:
                self._running = self._build()
            except Exception as exc:
                self._failed = f"{type(exc).__name__}: {exc}"
                self.stop(forget_failure=False)
                raise
        return self._running

    def _build(self) -> Service:
        self._folder = tempfile.TemporaryDirectory(prefix="plantcheck-svc-")
        folder = Path(self._folder.name)
        port = free_port()
        # every 10 s (at 3 s it took a third of a core), and the table's freshness test
        # still sees a diagnosis within its 10-s poll
        config = write_config(folder, port=port, period_s=10.0)
        start, truth = fill_store(folder, config)
        svc = start_service(config, port, truth, start)
        self._running = svc  # stopped by stop() if the wait below fails
        sticky = frozenset(k for k, t in truth.items() if t["S"] is not None)
        wait_diagnosed(svc.url, len(truth), sticky=sticky)
        return svc

    def stop(self, forget_failure: bool = True) -> None:
        if forget_failure:  # a later row of tests builds it again
            self._failed = None
        if self._running is not None:
            self._running.stop()
            self._running = None
        if self._folder is not None:
            self._folder.cleanup()
            self._folder = None

    def stop_unless_needed(self, next_fixtures: Iterable[str] | None) -> None:
        """Stop it unless the next test (its fixture names; None: no next test) uses it."""
        if next_fixtures is None or "service" not in next_fixtures:
            self.stop()


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def dump_dom(url: str, profile: Path, offline: bool = False, tz: str | None = None) -> str:
    """The DOM after the page's scripts ran, from headless Chromium; ``offline``: every host
    but loopback fails to resolve, as on a plant network without internet."""
    exe = _chromium()
    if exe is None:
        pytest.skip("Chromium is not installed (make test installs Debian's chromium as root)")
    out = subprocess.run(
        [
            exe,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={profile}",
            "--virtual-time-budget=5000",
            *(["--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1"] if offline else []),
            "--dump-dom",
            url,
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
        env={**os.environ, "TZ": tz} if tz else None,
    )
    return out.stdout
