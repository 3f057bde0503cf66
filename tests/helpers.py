"""Helpers shared by the tests (importable because pytest puts tests/ on sys.path)."""

from __future__ import annotations

import socket
import subprocess
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


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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
