"""Loops carry their area, unit and criticality (configuration) and the indices of their latest
diagnosis, so the loop table can sort the worst first and filter by area (issue 49).

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-27
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    have = {c["name"] for c in sa.inspect(op.get_bind()).get_columns("loops")}
    if "kpis" in have:
        return  # created by 0001 from the current schema
    with op.batch_alter_table("loops") as batch:
        batch.add_column(sa.Column("area", sa.String(64), nullable=False, server_default=""))
        batch.add_column(sa.Column("unit", sa.String(64), nullable=False, server_default=""))
        batch.add_column(sa.Column("criticality", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("kpis", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("loops") as batch:
        for name in ("kpis", "criticality", "unit", "area"):
            batch.drop_column(name)
