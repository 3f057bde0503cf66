"""Engines and migrations: the URL decides SQLite (embedded default) or PostgreSQL.

SQLite runs in WAL mode with ``synchronous=NORMAL`` and a busy timeout, so readers never block
the writer; PostgreSQL goes through asyncpg. Migrations are Alembic's (``migrations/``); the
service refuses to start on a database that is not at the newest revision and names the
command that fixes it (``plantcheck db upgrade``).
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import event, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError, OperationalError
from sqlalchemy.ext.asyncio import AsyncEngine, create_async_engine

from plantcheck.storage.errors import StorageError

if TYPE_CHECKING:
    from alembic.config import Config as AlembicConfig

MIGRATIONS = Path(__file__).with_name("migrations")

__all__ = ["MIGRATIONS", "StorageError", "upgrade"]


def _sqlite_pragmas(dbapi_conn: Any, _record: Any) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA journal_mode=WAL")
    cur.execute("PRAGMA synchronous=NORMAL")
    cur.execute("PRAGMA busy_timeout=10000")
    cur.execute("PRAGMA foreign_keys=ON")
    # the WAL shrinks to nothing each time a checkpoint resets it: a disk that fills shows at
    # the next commit, not minutes later once a WAL kept at its largest size is used up
    cur.execute("PRAGMA journal_size_limit=0")
    cur.close()


def sqlite_file(url: str) -> Path | None:
    """The database file of a SQLite ``url`` (None for another database, an in-memory one or a
    ``file:`` URI): what the checks of a missing file, a missing folder and a buffer sharing
    the database's disk look at."""
    parsed = make_url(url)
    db = parsed.database
    if (
        parsed.get_backend_name() != "sqlite"
        or not db
        or db == ":memory:"
        or db.startswith("file:")
    ):
        return None
    return Path(db)


def make_engine(url: str) -> AsyncEngine:
    """An async engine for ``url`` (``sqlite+aiosqlite:///FILE`` or ``postgresql+asyncpg://``)."""
    if url.startswith("sqlite"):
        engine = create_async_engine(url)
        event.listen(engine.sync_engine, "connect", _sqlite_pragmas)
        return engine
    return create_async_engine(url, pool_size=5, max_overflow=5, pool_pre_ping=True)


def alembic_config(url: str) -> AlembicConfig:
    # alembic (0.4-0.9 s to import) only where a database is migrated: a service that starts
    # on a migrated one reads the head revision from the migration files (``head_revision``)
    from alembic.config import Config as AlembicConfig

    cfg = AlembicConfig()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def upgrade(url: str) -> str:
    """Migrate the database at ``url`` to the newest revision (synchronous; not inside a
    running event loop). Returns that revision."""
    from alembic import command

    cfg = alembic_config(url)
    command.upgrade(cfg, "head")
    return head_revision()


_REVISION_LINE = re.compile(
    r"^(revision|down_revision)\b[^=\n]*=\s*(None|\"[^\"]*\"|'[^']*')", re.M
)


@cache
def head_revision() -> str:
    """The newest migration's revision: the one no other names as its ``down_revision``.

    Read from the migration files' own assignments rather than through Alembic's script
    directory, which imports Alembic and runs every migration module (about a second of each
    service's start on a slow machine); a test holds it equal to Alembic's head."""
    revisions: set[str] = set()
    below: set[str] = set()
    for path in sorted((MIGRATIONS / "versions").glob("*.py")):
        fields = dict(_REVISION_LINE.findall(path.read_text(encoding="utf-8")))
        if "revision" not in fields:
            raise RuntimeError(f"{path.name} names no revision")
        revisions.add(fields["revision"].strip("\"'"))
        if fields.get("down_revision", "None") != "None":
            below.add(fields["down_revision"].strip("\"'"))
    heads = revisions - below
    if len(heads) != 1:
        raise RuntimeError(f"the migrations have {len(heads)} heads: {sorted(heads)}")
    return heads.pop()


async def current_revision(engine: AsyncEngine) -> str | None:
    """The database's Alembic revision (None when it was never migrated)."""
    try:
        async with engine.connect() as conn:
            row = (await conn.execute(text("SELECT version_num FROM alembic_version"))).first()
    except (OperationalError, DBAPIError) as exc:
        msg = str(exc).lower()
        if "no such table" in msg or ("does not exist" in msg and "alembic_version" in msg):
            return None
        raise StorageError(f"cannot reach the database: {exc.orig}") from None
    except OSError as exc:
        # asyncpg resolves and connects itself: an unknown host or a refused port is an OSError
        where = engine.url.render_as_string(hide_password=True)
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise StorageError(
            f"cannot reach the database {where}: {reason}; check storage.url (host and port) "
            "and that the server runs"
        ) from None
    return None if row is None else str(row[0])


async def require_migrated(engine: AsyncEngine, config_hint: str = "") -> None:
    """Raise ``StorageError`` with the fixing command unless the schema is at the head."""
    have, want = await current_revision(engine), head_revision()
    if have != want:
        cfg = f" --config {config_hint}" if config_hint else ""
        state = "has no plantcheck schema" if have is None else f"is at revision {have}"
        raise StorageError(
            f"the database {engine.url.render_as_string(hide_password=True)} {state}, "
            f"plantcheck needs {want}: run `plantcheck db upgrade{cfg}`"
        )
