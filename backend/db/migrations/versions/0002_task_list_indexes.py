"""Indexes for GET /api/tasks over the stored history: newest change first, by requester.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-24
"""

from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_index("ix_tasks_updated_at", "tasks", ["updated_at"])
    op.create_index("ix_tasks_requester", "tasks", ["requester"])


def downgrade() -> None:
    op.drop_index("ix_tasks_requester", table_name="tasks")
    op.drop_index("ix_tasks_updated_at", table_name="tasks")
