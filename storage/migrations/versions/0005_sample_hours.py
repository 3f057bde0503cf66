"""Hourly roll-ups of the samples: the long trends kept for years after the samples are purged.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-24
"""

from __future__ import annotations

from alembic import op

from plantcheck.storage.schema import sample_hours

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    sample_hours.create(op.get_bind(), checkfirst=True)  # 0001 made it from the current schema


def downgrade() -> None:
    sample_hours.drop(op.get_bind(), checkfirst=True)
