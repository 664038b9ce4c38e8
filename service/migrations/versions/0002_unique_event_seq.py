"""one event per (vehicle, seq)

The history is contiguous by construction (``seq`` is the health version an event
produced, written under the version check); this constraint makes a second writer that
slipped past the check fail instead of forking the history.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-30
"""

from __future__ import annotations

from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("events") as batch:  # SQLite: copy-and-move
        batch.create_unique_constraint("uq_events_vehicle_seq", ["vehicle_id", "seq"])


def downgrade() -> None:
    with op.batch_alter_table("events") as batch:
        batch.drop_constraint("uq_events_vehicle_seq", type_="unique")
