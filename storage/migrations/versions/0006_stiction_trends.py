"""Each valve's stiction trend, stored when an estimate is stored (the report reads it).

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-25
"""

from __future__ import annotations

from alembic import op

from plantcheck.storage.schema import stiction_trends

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # 0001 made it from the current schema; an older database gets its valves' trends with
    # their next estimate
    stiction_trends.create(op.get_bind(), checkfirst=True)


def downgrade() -> None:
    stiction_trends.drop(op.get_bind(), checkfirst=True)
