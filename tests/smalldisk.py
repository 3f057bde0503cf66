"""A small real filesystem for the disk-fault tests (issue 45): a tmpfs of a few MB that the
test fills (a filler file takes every free byte) and frees again.

Mounting needs root (CAP_SYS_ADMIN); ``small_disk`` skips the test with that reason where it is
missing, so the suite stays green for a developer without it. CI runs as root.
"""

from __future__ import annotations

import errno
import os
import subprocess
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
