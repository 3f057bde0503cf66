"""The allocator settings of the processes that diagnose (``service/allocator.py``): glibc
takes them, and a process that cannot (no ``mallopt``) runs on."""

from __future__ import annotations

import subprocess
import sys

from plantcheck.service.allocator import tune_allocator


def test_glibc_takes_the_thresholds() -> None:
    # in a child process: the thresholds stay for the life of the process
    code = "from plantcheck.service.allocator import tune_allocator; print(tune_allocator())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ("True" if sys.platform == "linux" else "False")


def test_no_mallopt_is_no_error(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import ctypes

    class _NoMallopt:
        def __init__(self, name: object) -> None:
            pass

        def __getattr__(self, name: str) -> object:
            raise AttributeError(name)

    monkeypatch.setattr(ctypes, "CDLL", _NoMallopt)
    assert tune_allocator() is False
