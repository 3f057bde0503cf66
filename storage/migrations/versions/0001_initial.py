"""Initial schema: sources, loops, tags, samples, diagnoses, stiction estimates, actions.

On PostgreSQL with the TimescaleDB extension available, samples become a hypertable (one-day
chunks); without it, a plain table (TimescaleDB is supported, never required).

Revision ID: 0001
Revises:
Create Date: 2026-11-21
"""

from __future__ import annotations

from alembic import op
from sqlalchemy import text

from plantcheck.storage.schema import metadata

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    bind = op.get_bind()
    metadata.create_all(bind)
    if bind.dialect.name == "postgresql":
        has_tsdb = bind.execute(
            text("SELECT 1 FROM pg_available_extensions WHERE name = 'timescaledb'")
        ).first()
        if has_tsdb:
            op.execute("CREATE EXTENSION IF NOT EXISTS timescaledb")
            op.execute(
                "SELECT create_hypertable('samples', 'ts_us', "
                "chunk_time_interval => 86400000000, migrate_data => true)"
            )


def downgrade() -> None:
    metadata.drop_all(op.get_bind())
