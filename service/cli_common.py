"""Helpers shared by the command modules: one-line errors, writable output folders and
duration parsing."""

from __future__ import annotations

import os
import re
from pathlib import Path

import typer

_UNITS = {"s": 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``plantcheck: error: message`` on stderr; return the Exit to raise."""
    typer.echo(f"plantcheck: error: {message}", err=True)
    return typer.Exit(code)


def writable_folder(folder: Path, option: str) -> None:
    """Create ``folder`` if needed and check that it can be written, naming ``option``."""
    if folder.exists() and not folder.is_dir():
        raise fail(f"{option}: {folder} is a file, not a folder; choose a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise fail(
            f"{option}: cannot create {folder} ({exc.strerror}); choose a writable path"
        ) from None
    if not os.access(folder, os.W_OK):
        raise fail(f"{option}: {folder} is not writable; choose a writable path")


def parse_duration(text: str) -> float:
    """``90``, ``90s``, ``15m``, ``2h``, ``1d``, ``1h30m`` → seconds (ValueError otherwise)."""
    s = text.strip().lower()
    if re.fullmatch(r"\d+(\.\d+)?", s):
        return float(s)
    parts = re.findall(r"(\d+(?:\.\d+)?)\s*(min|s|m|h|d)", s)
    if not parts or "".join(f"{a}{b}" for a, b in parts) != s.replace(" ", ""):
        raise ValueError(f"{text!r} is not a duration; use e.g. 3600, 90s, 15m, 2h or 1d")
    return sum(float(a) * _UNITS[b] for a, b in parts)


def parse_host_port(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """``HOST:PORT``, ``:PORT`` or ``PORT`` → (host, port) (ValueError otherwise)."""
    host, _, port = text.rpartition(":")
    host = host.strip("[]") or default_host
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"{text!r} is not HOST:PORT (port 0..65535)")
    return host, int(port)
