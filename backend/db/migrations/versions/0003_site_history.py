"""Site history and the editors' draft: every published version with who and when.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-26
"""

import time

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    versions = op.create_table(
        "site_versions",
        sa.Column("version", sa.Integer, primary_key=True, autoincrement=False),
        sa.Column("data", sa.JSON, nullable=False),
        sa.Column("published_by", sa.String(64), nullable=False),
        sa.Column("published_at", sa.Float, nullable=False),
        sa.Column("note", sa.Text, nullable=False),
    )
    op.create_table(
        "site_draft",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("revision", sa.Integer, nullable=False),
        sa.Column("base_version", sa.Integer, nullable=False),
        sa.Column("data", sa.JSON, nullable=False),
        sa.Column("updated_by", sa.String(64), nullable=False),
        sa.Column("updated_at", sa.Float, nullable=False),
    )
    # The site stored before history existed becomes its first kept version.
    site = sa.table("site", sa.column("version", sa.Integer), sa.column("data", sa.JSON))
    row = op.get_bind().execute(sa.select(site.c.version, site.c.data)).first()
    if row is not None:
        op.bulk_insert(
            versions,
            [
                {
                    "version": row.version,
                    "data": row.data,
                    "published_by": "",
                    "published_at": time.time(),
                    "note": "stored before site history was kept",
                }
            ],
        )


def downgrade() -> None:
    op.drop_table("site_draft")
    op.drop_table("site_versions")
