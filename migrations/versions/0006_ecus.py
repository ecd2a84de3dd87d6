"""ECUs: an uploaded A2L (ASAM MCD-2 MC) with the ECU's current values (a HEX or S19 memory
image, a DCM or a CDFX file), kept as the bytes the user sent (docs/calibration.md).

The A2L is parsed on demand into a file cache keyed by its SHA-256; the row keeps the hash
and the number of characteristics so a list never parses anything.

Revision ID: 0006
Revises: 0005
Create Date: 2026-12-03
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

# revision identifiers, used by Alembic.
revision: str = "0006"
down_revision: str | Sequence[str] | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "ecus",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("a2l_sha256", sa.String(length=64), nullable=False),
        sa.Column("a2l", sa.LargeBinary(), nullable=False),
        sa.Column("characteristics", sa.Integer(), nullable=False),
        sa.Column("values_format", sa.String(length=8), nullable=True),
        sa.Column("values", sa.LargeBinary(), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_ecus")),
        sqlite_autoincrement=True,
    )


def downgrade() -> None:
    op.drop_table("ecus")
