"""Stiction estimates name their method and whether they passed their rules.

S and J now come from the Hammerstein identification, the stick-slip events, the PV(OP)
ellipse or the stem position; the trend report keeps one method per trend. Earlier rows were
all reliable Hammerstein (or stem-position) estimates, which the server defaults say, and the
stem-position ones are marked as such from their ``source``.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    have = {c["name"] for c in sa.inspect(op.get_bind()).get_columns("stiction_estimates")}
    if "method" in have:
        return  # created by 0001 from the current schema
    with op.batch_alter_table("stiction_estimates") as batch:
        batch.add_column(
            sa.Column("method", sa.String(16), nullable=False, server_default="hammerstein")
        )
        batch.add_column(
            sa.Column("reliable", sa.Boolean(), nullable=False, server_default=sa.true())
        )
    op.execute("UPDATE stiction_estimates SET method = 'measured' WHERE source = 'mv'")


def downgrade() -> None:
    with op.batch_alter_table("stiction_estimates") as batch:
        batch.drop_column("reliable")
        batch.drop_column("method")
