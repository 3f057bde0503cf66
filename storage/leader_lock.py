"""The one-scheduler guarantee on PostgreSQL: a session advisory lock (issue 28).

The process that holds the lock schedules the diagnosis and reads the sources it owns; a second
``plantcheck run`` on the same database waits as a standby and takes over within one poll
interval of the holder's death. PostgreSQL releases a session lock when the session ends, and
the kernel closes a killed process's socket at once, so the lock is free as soon as the server
sees the connection drop (no lease to expire). The lock lives on a connection of its own, in
autocommit (an idle transaction held for weeks would trip ``idle_in_transaction_session_
timeout``).
"""

from __future__ import annotations

import contextlib

from sqlalchemy import text
from sqlalchemy.ext.asyncio import AsyncConnection

from plantcheck.storage.store import Store

SCHEDULER_LOCK_KEY = 0x706C616E74636B
"""``pg_advisory_lock`` key of the scheduler role ("plantck" in ASCII)."""


class LeaderLock:
    """``try_acquire()`` / ``still_held()`` / ``release()`` of the scheduler lock."""

    def __init__(self, store: Store, key: int = SCHEDULER_LOCK_KEY) -> None:
        if store.dialect != "postgresql":
            raise ValueError("the scheduler lock needs PostgreSQL (SQLite has one process)")
        self.store = store
        self.key = key
        self._conn: AsyncConnection | None = None

    @property
    def held(self) -> bool:
        """Whether this process believes it holds the lock (``still_held`` checks)."""
        return self._conn is not None

    async def try_acquire(self) -> bool:
        """Take the lock if nobody holds it; False (and no error) when the database is down."""
        if self._conn is not None:
            return True
        conn = None
        try:
            conn = await self.store.engine.connect()
            conn = await conn.execution_options(isolation_level="AUTOCOMMIT")
            got = bool(
                (
                    await conn.execute(text("SELECT pg_try_advisory_lock(:k)"), {"k": self.key})
                ).scalar_one()
            )
        except Exception:
            got = False
        if got:
            self._conn = conn
        elif conn is not None:
            with contextlib.suppress(Exception):
                await conn.close()
        return got

    async def still_held(self) -> bool:
        """Whether the lock's session is alive (a dropped session has lost the lock)."""
        if self._conn is None:
            return False
        try:
            await self._conn.execute(text("SELECT 1"))
            return True
        except Exception:
            await self._drop()
            return False

    async def release(self) -> None:
        if self._conn is not None:
            with contextlib.suppress(Exception):
                await self._conn.execute(text("SELECT pg_advisory_unlock(:k)"), {"k": self.key})
        await self._drop()

    async def _drop(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            with contextlib.suppress(Exception):
                await conn.close()
