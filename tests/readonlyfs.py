"""A pass-through FUSE filesystem that turns read-only and writable again on a signal: the
disk-fault tests' "remounted read-only" (issue 45).

The kernel refuses to remount a filesystem read-only while a process holds a file open for
writing (SQLite always does), and ext4's forced read-only after an error cannot be undone
without unmounting: neither can show a disk that turns read-only and back under a running
service. This filesystem can: it passes every call through to ``SOURCE`` and, while the file
``SWITCH`` exists (outside the mount), answers every write with EROFS, as a read-only disk
does. (A file, not a signal: Python runs signal handlers only when libfuse's loop returns.)

    python tests/readonlyfs.py SOURCE MOUNTPOINT SWITCH   (root, /dev/fuse, libfuse3, mfusepy)
"""

from __future__ import annotations

import errno
import os
import sys
from typing import Any

import mfusepy as fuse

WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND


class ReadOnlyToggle(fuse.Operations):  # type: ignore[misc]
    use_ns = True
    """Pass-through to ``root``; every write fails with EROFS while ``switch`` exists."""

    def __init__(self, root: str, switch: str) -> None:
        self.root = os.path.realpath(root)
        self.switch = switch

    @property
    def readonly(self) -> bool:
        return os.path.exists(self.switch)

    def _full(self, path: str) -> str:
        return os.path.join(self.root, path.lstrip("/"))

    def _writable(self) -> None:
        if self.readonly:
            raise fuse.FuseOSError(errno.EROFS)

    def access(self, path: str, amode: int) -> int:
        if amode & os.W_OK and self.readonly:
            raise fuse.FuseOSError(errno.EROFS)
        if not os.access(self._full(path), amode):
            raise fuse.FuseOSError(errno.EACCES)
        return 0

    def getattr(self, path: str, fh: Any = None) -> dict[str, Any]:
        st = os.lstat(self._full(path))
        keys = ("st_atime", "st_ctime", "st_gid", "st_mode", "st_mtime", "st_nlink", "st_size")
        return {k: getattr(st, k) for k in (*keys, "st_uid")}

    def readdir(self, path: str, fh: int) -> list[str]:
        return [".", "..", *os.listdir(self._full(path))]

    def statfs(self, path: str) -> dict[str, Any]:
        sv = os.statvfs(self._full(path))
        keys = ("f_bavail", "f_bfree", "f_blocks", "f_bsize", "f_favail", "f_ffree", "f_files")
        return {k: getattr(sv, k) for k in (*keys, "f_flag", "f_frsize", "f_namemax")}

    def open(self, path: str, flags: int) -> int:
        if flags & WRITE_FLAGS:
            self._writable()
        return os.open(self._full(path), flags)

    def create(self, path: str, mode: int, fi: Any = None) -> int:
        self._writable()
        return os.open(self._full(path), os.O_RDWR | os.O_CREAT, mode)

    def read(self, path: str, size: int, offset: int, fh: int) -> bytes:
        return os.pread(fh, size, offset)

    def write(self, path: str, data: bytes, offset: int, fh: int) -> int:
        self._writable()
        return os.pwrite(fh, data, offset)

    def truncate(self, path: str, length: int, fh: Any = None) -> int:
        self._writable()
        if fh is not None:
            os.ftruncate(fh, length)
        else:
            os.truncate(self._full(path), length)
        return 0

    def fsync(self, path: str, datasync: int, fh: int) -> int:
        self._writable()
        os.fsync(fh)
        return 0

    def flush(self, path: str, fh: int) -> int:
        return 0

    def release(self, path: str, fh: int) -> int:
        os.close(fh)
        return 0

    def unlink(self, path: str) -> int:
        self._writable()
        os.unlink(self._full(path))
        return 0

    def rename(self, old: str, new: str) -> int:
        self._writable()
        os.rename(self._full(old), self._full(new))
        return 0

    def mkdir(self, path: str, mode: int) -> int:
        self._writable()
        os.mkdir(self._full(path), mode)
        return 0

    def chmod(self, path: str, mode: int) -> int:
        self._writable()
        os.chmod(self._full(path), mode)
        return 0

    def utimens(self, path: str, times: Any = None) -> int:
        self._writable()
        os.utime(self._full(path), ns=times)
        return 0


def main() -> None:
    source, mountpoint, switch = sys.argv[1:4]
    fuse.FUSE(ReadOnlyToggle(source, switch), mountpoint, foreground=True, nothreads=True)


if __name__ == "__main__":
    main()
