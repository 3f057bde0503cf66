"""Shared test helpers: running the real ``plantcheck`` command in a subprocess."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from helpers import RunCli


@pytest.fixture
def run_cli() -> RunCli:
    """Run ``plantcheck ARGS`` as a user would (new process), return the completed process."""

    def _run(*args: str, timeout: float = 600.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "plantcheck.service.cli", *args],
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )

    return _run


@pytest.fixture
def repo_root() -> Path:
    return Path(__file__).resolve().parents[1]
