"""SQLite: cluster samples on (tag_id, ts_us) (a WITHOUT ROWID table).

Samples of all tags arrive interleaved in time, so in a rowid table one tag's window is an index
range scan plus one table lookup per row; clustered on the primary key it is one sequential
scan, about 2.5x faster for the scheduler's window reads. The table is rebuilt (copied), which
takes about a second per two million samples. PostgreSQL is left as it is.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-21
"""

from __future__ import annotations

from alembic import op
from sqlalchemy import text

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

_COLUMNS = "tag_id, ts_us, recv_us, value, status"


def _rebuild(with_rowid: bool) -> None:
    bind = op.get_bind()
    if bind.dialect.name != "sqlite":
        return
    sql = bind.execute(text("SELECT sql FROM sqlite_master WHERE name = 'samples'")).scalar_one()
    if ("WITHOUT ROWID" not in sql.upper()) == with_rowid:
        return  # already in the wanted form (created by 0001 from the current schema)
    suffix = "" if with_rowid else " WITHOUT ROWID"
    op.execute(
        "CREATE TABLE samples_new (tag_id INTEGER NOT NULL, ts_us BIGINT NOT NULL, "
        "recv_us BIGINT NOT NULL, value FLOAT, status BIGINT NOT NULL, "
        f"PRIMARY KEY (tag_id, ts_us)){suffix}"
    )
    op.execute(f"INSERT INTO samples_new ({_COLUMNS}) SELECT {_COLUMNS} FROM samples")
    op.execute("DROP TABLE samples")
    op.execute("ALTER TABLE samples_new RENAME TO samples")


def upgrade() -> None:
    _rebuild(with_rowid=False)


def downgrade() -> None:
    _rebuild(with_rowid=True)
