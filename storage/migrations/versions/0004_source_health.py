"""Source health reports: collectors at the plant tell the central service how their sources are.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-24
"""

from __future__ import annotations

from alembic import op

from plantcheck.storage.schema import source_health

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    source_health.create(op.get_bind(), checkfirst=True)  # 0001 made it from the current schema


def downgrade() -> None:
    source_health.drop(op.get_bind(), checkfirst=True)
