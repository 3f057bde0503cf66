"""The alert outbox (issue 49 item 4).

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-27
"""

from __future__ import annotations

from alembic import op

from plantcheck.storage.schema import alerts

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # 0001 made it from the current schema; an older database gets it here
    alerts.create(op.get_bind(), checkfirst=True)


def downgrade() -> None:
    alerts.drop(op.get_bind(), checkfirst=True)
