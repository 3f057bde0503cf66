"""service/logs.py: one logging configuration, libraries quiet, plain or JSON lines."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest
from helpers import RunCli

from plantcheck.service.logs import configure_logging


@pytest.fixture(autouse=True)
def _restore_logging() -> object:
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield None
    root.handlers[:] = handlers
    root.setLevel(level)


def test_libraries_stay_at_warning_unless_debug() -> None:
    configure_logging("info")
    assert logging.getLogger("asyncua").getEffectiveLevel() == logging.WARNING
    assert logging.getLogger("asyncua.client.ua_client").getEffectiveLevel() == logging.WARNING
    assert logging.getLogger("plantcheck.connectors").getEffectiveLevel() == logging.INFO
    configure_logging("debug")
    assert logging.getLogger("asyncua").getEffectiveLevel() == logging.DEBUG
    configure_logging("error")
    assert logging.getLogger("pymodbus").getEffectiveLevel() == logging.ERROR


def test_the_demo_keeps_library_warnings_off_its_terminal(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A loaded demo printed asyncua's "Future for request id 120 is already done" at its
    stop (a reply that crossed the session's close); the demo's terminal shows plantcheck's
    progress, so its libraries log errors only (issue 47 item 6), and everything at debug."""
    configure_logging("warning", libraries="error")
    logging.getLogger("asyncua.client.ua_client").warning("Future for request id 120 is done")
    logging.getLogger("plantcheck.service").warning("ours")
    err = capsys.readouterr().err
    assert "asyncua" not in err and "ours" in err
    configure_logging("debug", libraries="error")
    assert logging.getLogger("asyncua").getEffectiveLevel() == logging.DEBUG


def test_json_lines(capsys: pytest.CaptureFixture[str]) -> None:
    configure_logging("info", "json")
    logging.getLogger("plantcheck.test").warning("source %s down", "plc1")
    line = capsys.readouterr().err.strip().splitlines()[-1]
    record = json.loads(line)
    assert record["level"] == "warning" and record["message"] == "source plc1 down"
    assert record["logger"] == "plantcheck.test" and record["time"].endswith("Z")


def test_cli_takes_the_options(run_cli: RunCli) -> None:
    r = run_cli("--log-level", "warning", "--log-format", "json", "--version")
    assert r.returncode == 0 and "plantcheck" in r.stdout
    bad = run_cli("--log-level", "loud", "oscillation", "x.csv", "--column", "op")
    assert bad.returncode == 2 and "--log-level" in bad.stderr


def test_a_library_error_is_one_line_without_its_traceback(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """asyncua's "Publish iteration crashed" traceback at every lost connection (issue 27)."""
    configure_logging("info")
    try:
        raise ConnectionError("Connection is closed")
    except ConnectionError:
        logging.getLogger("asyncua.client.ua_session").exception("Publish iteration crashed")
        logging.getLogger("plantcheck.scheduler").exception("a bug of ours")
    err = capsys.readouterr().err
    assert "Publish iteration crashed (ConnectionError: Connection is closed)" in err
    assert err.count("Traceback") == 1 and err.index("Traceback") > err.index("a bug of ours")


def test_the_root_options_reach_the_command(tmp_path: Path) -> None:
    """``--log-level error`` quiets the simulator's asyncua notices (issue 47: typer's own copy
    of click hid the root options from the commands, which logged at their default)."""
    import subprocess
    import sys

    from helpers import free_port

    def stderr_of(*root: str) -> str:
        url = f"opc.tcp://127.0.0.1:{free_port()}/x/"
        proc = subprocess.Popen(
            [sys.executable, "-m", "plantcheck.service.cli", *root, "simulate", "--opcua", url,
             "--modbus", "off", "--admin", "off", "--quiet"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert proc.stderr is not None
        seen = ""
        while "plantcheck simulator" not in seen:  # its banner, once it serves
            line = proc.stderr.readline()
            assert line, seen
            seen += line
        proc.terminate()
        return seen + proc.communicate(timeout=30)[1]

    assert "WARNING asyncua" in stderr_of()
    assert "WARNING" not in stderr_of("--log-level", "error")
