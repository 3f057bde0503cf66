"""The plant-wide oscillation groups of each pass (issue 49 item 3).

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-27
"""

from __future__ import annotations

from alembic import op

from plantcheck.storage.schema import plant_oscillations

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # 0001 made it from the current schema; an older database gets it here
    plant_oscillations.create(op.get_bind(), checkfirst=True)


def downgrade() -> None:
    plant_oscillations.drop(op.get_bind(), checkfirst=True)
