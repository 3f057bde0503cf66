"""Helpers shared by the tests (importable because pytest puts tests/ on sys.path)."""

from __future__ import annotations

import itertools
import json
import os
import socket
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from plantcheck.core.toml_config import ConfigError
from plantcheck.diagnosis.result import action_for, priority_of, state_of
from plantcheck.service.config import Config, LoopConfig, SourceConfig
from plantcheck.simulator.cases import Case
from plantcheck.simulator.plant_windows import generate_plant_window_cases
from plantcheck.storage.results import Verdict
from plantcheck.storage.store import LoopRow

RunCli = Callable[..., subprocess.CompletedProcess[str]]
ComputedOnce = Callable[[str, Callable[[], Any]], Any]
"""``computed_once``'s function (tests/conftest.py): a JSON value computed once per run."""

T0 = 1_767_225_600_000_000
"""2026-01-01T00:00:00Z in µs: the start of the store tests' samples."""


def one_loop_config() -> Config:
    """One flow loop FIC1 (SP, PV, OP) on a Modbus source: the store tests' configuration."""
    return Config(
        source=[SourceConfig(name="plc", protocol="modbus", port=5020)],
        loop=[
            LoopConfig(id="FIC1", type="flow", source="plc", sp="hr:10:float32",
                       pv="hr:12:float32", op="hr:14:float32")
        ],
    )  # fmt: skip


def verdict_of(
    row: LoopRow, at_us: int, cause: str, S: float | None = None, J: float | None = None
) -> Verdict:
    """A stored verdict of ``cause`` for a 1-h window ending at ``at_us``, with its action
    (without diagnosing: the store and API tests' verdicts)."""
    a = action_for(cause, S, J)
    return Verdict(
        row,
        at_us,
        at_us - 3_600_000_000,
        at_us,
        cause,
        state_of(cause),
        {"cause": cause},
        a["code"],
        a["text"],
        priority_of(cause),
        S,
        J,
    )


EPHEMERAL_RANGE = Path("/proc/sys/net/ipv4/ip_local_port_range")
PORT_POOL_START = 10_000
"""The first port ``free_port`` hands out; its pool ends where the kernel's ephemeral range
(the ports of outgoing connections) begins."""
PORT_SLICES = 16
"""The pool is cut into this many slices, one per xdist worker (``gw0`` … ``gw15``)."""


def _ephemeral_start() -> int:
    try:
        return int(EPHEMERAL_RANGE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32_768  # Linux's default


def _port_slice() -> range:
    """This process' share of the ports below the ephemeral range: its xdist worker's slice,
    or (outside xdist) the slice its process id falls on."""
    width = (_ephemeral_start() - PORT_POOL_START) // PORT_SLICES
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    k = int(worker[2:]) if worker[2:].isdigit() else os.getpid()
    lo = PORT_POOL_START + (k % PORT_SLICES) * width
    return range(lo, lo + max(width, 0))


_turn = itertools.count(os.getpid())
"""This process' turns through its slice, from a start its process id sets."""


def _bindable(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now, and that no other test
    process is handed and no outgoing connection takes before the test binds it.

    A port the kernel picks (``bind(("127.0.0.1", 0))``) comes from the ephemeral range,
    which outgoing connections draw from too: under load a client of another test took one
    between the pick and the server's bind ("address already in use", seen once in a full
    run). This process' ports come from its own slice below that range instead, in turn
    from a start its process id sets, so none comes back until the slice's ~1,400 are used.
    Where the ephemeral range leaves no room below it, the kernel picks as before."""
    ports = _port_slice()
    if len(ports) < 100:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            return int(s.getsockname()[1])
    for _ in range(len(ports)):
        port = ports[next(_turn) % len(ports)]
        if _bindable(port):
            return port
    raise RuntimeError(f"no free port on 127.0.0.1 in {ports.start}-{ports.stop - 1}")


def modules_loaded(imports: str, prefixes: tuple[str, ...]) -> list[str]:
    """The modules whose names start with one of ``prefixes`` that a new Python process has
    loaded after ``import IMPORTS`` (a comma-separated list), sorted."""
    code = (
        f"import json, sys, {imports}\n"
        f"print(json.dumps(sorted(m for m in sys.modules if m.startswith({prefixes!r}))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return list(json.loads(out.stdout))


def case_folders(name: str) -> list[Path]:
    """The case folders of ``tests/NAME`` (Telegraf style: one input file and the
    ``expected_error.txt`` it must be refused with; empty: it is valid)."""
    root = Path(__file__).parent / name
    return sorted(p for p in root.iterdir() if p.is_dir())


def check_refusal(path: Path, expected: str, load: Callable[[Path], object]) -> None:
    """``load(path)`` succeeds when ``expected`` is empty, else raises ``ConfigError`` with
    one line that starts with the file and holds ``expected``."""
    if not expected:
        load(path)
        return
    with pytest.raises(ConfigError) as info:
        load(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert expected in message, message
    assert "\n" not in message


def plant_window(name: str) -> Case:
    """The one generated plant window of this name, seeds 1 and 2 (the windows of
    ``benchmarks/plant_window_accuracy.py``)."""
    (case,) = [
        pc.case
        for seed in (1, 2)
        for pc in generate_plant_window_cases(seed=seed)
        if pc.case.name == name
    ]
    return case
