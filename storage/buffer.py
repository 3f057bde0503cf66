"""Local durable buffer: samples wait here, in order, while the store is unreachable.

A small SQLite file (stdlib ``sqlite3``, WAL) with an autoincrement sequence, so samples leave
in the order they arrived. At most ``max_samples`` are kept: what does not fit is dropped,
counted (``dropped``) and reported by the writer; nothing else is ever lost. A write that
the disk refuses (full, read-only, I/O error) is rolled back and raised as
``BufferUnavailableError``: the writer keeps those samples in memory and tries again (issue 45).
"""

from __future__ import annotations

import contextlib
import sqlite3
from collections.abc import Sequence
from pathlib import Path

from plantcheck.core.samples import Sample
from plantcheck.storage.errors import StorageError


class BufferUnavailableError(StorageError):
    """The buffer's disk refused a read or write (full, read-only, failing); nothing changed."""


class DurableBuffer:
    """FIFO of samples on disk."""

    def __init__(self, path: Path, max_samples: int) -> None:
        self.path = path
        self.max_samples = max_samples
        self.dropped = 0
        try:
            self._db = sqlite3.connect(str(path), isolation_level=None, check_same_thread=False)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute("PRAGMA journal_size_limit=0")  # a full disk shows at once
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS pending (seq INTEGER PRIMARY KEY AUTOINCREMENT, "
                "tag_id INTEGER, ts_us INTEGER, recv_us INTEGER, value REAL, status INTEGER)"
            )
            self._size = int(self._db.execute("SELECT count(*) FROM pending").fetchone()[0])
        except sqlite3.Error as exc:
            # without its buffer the service would lose every sample of a store outage
            raise StorageError(
                f"storage.buffer_path: cannot open the durable buffer {path} ({exc}); point it "
                "at a file in a folder the service can write"
            ) from None

    def __len__(self) -> int:
        return self._size

    def append(self, rows: Sequence[Sample]) -> int:
        """Keep ``rows`` (as many as fit); returns how many were dropped."""
        room = max(0, self.max_samples - self._size)
        keep = rows[:room]
        lost = len(rows) - len(keep)
        if keep:
            try:
                self._db.execute("BEGIN")
                self._db.executemany(
                    "INSERT INTO pending (tag_id, ts_us, recv_us, value, status) "
                    "VALUES (?,?,?,?,?)",
                    keep,
                )
                self._db.execute("COMMIT")
            except sqlite3.Error as exc:
                self._rollback()
                raise BufferUnavailableError(f"durable buffer {self.path}: {exc}") from None
            self._size += len(keep)
        self.dropped += lost
        return lost

    def peek(self, n: int) -> tuple[int, list[Sample]]:
        """The oldest ``n`` samples and the sequence number of the last of them."""
        try:
            rows = self._db.execute(
                "SELECT seq, tag_id, ts_us, recv_us, value, status FROM pending ORDER BY seq "
                "LIMIT ?",
                (n,),
            ).fetchall()
        except sqlite3.Error as exc:
            raise BufferUnavailableError(f"durable buffer {self.path}: {exc}") from None
        if not rows:
            return 0, []
        return int(rows[-1][0]), [Sample(*r[1:]) for r in rows]

    def newest(self) -> dict[int, tuple[int, int]]:
        """Per tag, the source time (µs) and status of its newest buffered sample."""
        cur = self._db.execute(
            "SELECT tag_id, ts_us, status FROM pending p WHERE ts_us = "
            "(SELECT max(ts_us) FROM pending q WHERE q.tag_id = p.tag_id)"
        )
        return {int(t): (int(ts), int(st)) for t, ts, st in cur.fetchall()}

    def remove_through(self, seq: int) -> None:
        """Forget every sample up to ``seq`` (after they were stored)."""
        try:
            cur = self._db.execute("DELETE FROM pending WHERE seq <= ?", (seq,))
        except sqlite3.Error as exc:
            self._rollback()
            raise BufferUnavailableError(f"durable buffer {self.path}: {exc}") from None
        self._size = max(0, self._size - cur.rowcount)

    def _rollback(self) -> None:
        """Leave no transaction open after a refused write (the next one starts clean)."""
        if self._db.in_transaction:
            with contextlib.suppress(sqlite3.Error):
                self._db.execute("ROLLBACK")

    def close(self) -> None:
        with contextlib.suppress(sqlite3.Error):
            self._db.close()
