"""Booked and recurring tours (backend/bookings): the bookings, their history, and one row per
occurrence started (written before its task is created: no occurrence started twice).

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-28
"""

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "bookings",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("data", sa.JSON, nullable=False),
        sa.Column("status", sa.String(16), nullable=False, index=True),
        sa.Column("updated_at", sa.Float, nullable=False),
    )
    op.create_table(
        "booking_history",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("booking", sa.String(32), nullable=False, index=True),
        sa.Column("at", sa.Float, nullable=False),
        sa.Column("by", sa.String(64), nullable=False, server_default=""),
        sa.Column("action", sa.String(32), nullable=False),
        sa.Column("detail", sa.JSON, nullable=False),
    )
    op.create_table(
        "booking_starts",
        sa.Column("booking", sa.String(32), primary_key=True),
        sa.Column("occurrence", sa.Float, primary_key=True),
        sa.Column("started_at", sa.Float, nullable=False),
        sa.Column("task_id", sa.String(32), nullable=True),
        sa.Column("outcome", sa.String(16), nullable=False),
        sa.Column("reason", sa.String(500), nullable=False, server_default=""),
    )


def downgrade() -> None:
    op.drop_table("booking_starts")
    op.drop_table("booking_history")
    op.drop_table("bookings")
