"""Real filesystems that fail for the disk-fault tests (issue 45): ``small_disk``, a tmpfs of a
few MB that the test fills (a filler file takes every free byte) and frees again, and
``readonly_disk``, a pass-through FUSE filesystem (``readonlyfs.py``) that the test turns
read-only and writable again.

Mounting needs root (CAP_SYS_ADMIN), and the FUSE one ``/dev/fuse``, libfuse3 and mfusepy (the
Makefile and the dev extra install them); each skips the test naming what is missing, so the
suite stays green for a developer without them. CI runs as root.
"""

from __future__ import annotations

import ctypes.util
import errno
import importlib.util
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


class SmallDisk:
    """A mounted tmpfs: ``fill()`` leaves it with no free byte, ``free()`` undoes that."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.filler = path / "filler.bin"

    def fill(self) -> None:
        """Take every free byte (ENOSPC ends the writing, as on a disk that filled up)."""
        chunk = b"\0" * 65536
        with self.filler.open("ab", buffering=0) as f:
            for size in (65536, 4096, 512, 1):
                try:
                    while True:
                        f.write(chunk[:size])
                except OSError as exc:
                    if exc.errno != errno.ENOSPC:
                        raise

    def free(self) -> None:
        self.filler.unlink(missing_ok=True)

    fault = fill
    recover = free

    def free_bytes(self) -> int:
        st = os.statvfs(self.path)
        return st.f_bavail * st.f_frsize


def mount_reason() -> str:
    """Why a tmpfs cannot be mounted here ("" when it can)."""
    if os.geteuid() != 0:
        return "the disk-fault tests mount a small tmpfs, which needs root"
    return ""


@contextmanager
def small_disk(path: Path, size_mb: int = 16) -> Iterator[SmallDisk]:
    """A tmpfs of ``size_mb`` MB mounted at ``path`` (the test is skipped where it cannot be)."""
    reason = mount_reason()
    if reason:
        pytest.skip(reason)
    path.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_mb}m", "tmpfs", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"the disk-fault tests mount a small tmpfs, refused here: {done.stderr}")
    try:
        yield SmallDisk(path)
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True, check=False)


class ReadOnlyDisk:
    """A mounted ``readonlyfs``: ``fault()`` turns it read-only, ``recover()`` writable."""

    def __init__(self, path: Path, switch: Path) -> None:
        self.path = path
        self.switch = switch

    def fault(self) -> None:
        self.switch.touch()

    def recover(self) -> None:
        self.switch.unlink(missing_ok=True)


def fuse_reason() -> str:
    """Why ``readonly_disk`` cannot run here ("" when it can)."""
    if os.geteuid() != 0:
        return "the read-only disk test mounts a FUSE filesystem, which needs root"
    if not os.path.exists("/dev/fuse"):
        return "the read-only disk test needs /dev/fuse"
    if ctypes.util.find_library("fuse3") is None:
        return "the read-only disk test needs libfuse3 (Debian package libfuse3-3)"
    if importlib.util.find_spec("mfusepy") is None:
        return "the read-only disk test needs mfusepy (pip install -e '.[dev]')"
    return ""


@contextmanager
def readonly_disk(path: Path, scratch: Path) -> Iterator[ReadOnlyDisk]:
    """A FUSE pass-through of ``scratch/ro-source`` mounted at ``path``, read-only while
    ``scratch/ro-switch`` exists (the test is skipped where it cannot be mounted)."""
    reason = fuse_reason()
    if reason:
        pytest.skip(reason)
    source, switch = scratch / "ro-source", scratch / "ro-switch"
    source.mkdir(parents=True, exist_ok=True)
    path.mkdir(parents=True, exist_ok=True)
    proc = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("readonlyfs.py")), str(source), str(path),
         str(switch)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )  # fmt: skip
    deadline = time.monotonic() + 15.0
    while not os.path.ismount(path):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
            pytest.skip(f"the read-only disk test could not mount its FUSE filesystem: {err}")
        time.sleep(0.05)
    try:
        yield ReadOnlyDisk(path, switch)
    finally:
        switch.unlink(missing_ok=True)
        subprocess.run(["umount", "-l", str(path)], capture_output=True, check=False)
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
