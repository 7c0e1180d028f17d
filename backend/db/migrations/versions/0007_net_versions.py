"""Nets published from the RoboGraph editor, every version kept (docs/nets.md, "Publish").

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-28
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "net_versions",
        sa.Column("seq", sa.Integer, primary_key=True, autoincrement=False),
        sa.Column("net", sa.String(100), nullable=False),
        sa.Column("version", sa.Integer, nullable=False),
        sa.Column("pnml", sa.Text, nullable=False),
        sa.Column("published_by", sa.String(64), nullable=False, server_default=""),
        sa.Column("published_at", sa.Float, nullable=False),
        sa.Column("note", sa.Text, nullable=False, server_default=""),
        sa.UniqueConstraint("net", "version", name="uq_net_versions_net_version"),
    )
    op.create_index("ix_net_versions_net", "net_versions", ["net"])


def downgrade() -> None:
    op.drop_index("ix_net_versions_net", "net_versions")
    op.drop_table("net_versions")
