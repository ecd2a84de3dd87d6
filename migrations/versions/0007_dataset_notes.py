"""Datasets keep what ingest said about an upload: its ``notes`` (channels skipped, dropped,
masked or resampled, docs/data-formats.md#multi-rate), so ``GET /api/datasets/{id}`` gives
what the upload response gave.

The masked samples per channel need no column: they live in each entry of the ``channels``
JSON as ``"masked": n`` when ``n > 0``. Datasets stored before this revision have no notes
(``NULL``) and no masked counts, which reads as "nothing to say".

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-03
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

# revision identifiers, used by Alembic.
revision: str = "0007"
down_revision: str | Sequence[str] | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("datasets", schema=None) as batch_op:
        batch_op.add_column(sa.Column("notes", sa.JSON(), nullable=True))


def downgrade() -> None:
    # SQLite drops the column by rebuilding the table: keep its ids never reused (0005).
    with op.batch_alter_table(
        "datasets", schema=None, table_kwargs={"sqlite_autoincrement": True}
    ) as batch_op:
        batch_op.drop_column("notes")
