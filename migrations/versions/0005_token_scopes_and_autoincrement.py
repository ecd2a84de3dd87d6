"""Token scopes, and ids that are never reused.

A token carries scopes (``read``, ``run``, ``admin``; stored comma-separated). Tokens that
exist before this revision get all three, so nothing an existing client does breaks.

On SQLite every table is rebuilt with ``AUTOINCREMENT`` (batch mode: copy, drop, rename, with
foreign keys off, see ``migrations/env.py``): without it SQLite hands the id of a deleted row
to the next insert, and an old link (``/runs/12``) would show another run. PostgreSQL
sequences never reuse an id, so there is nothing to do there.

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-15
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

# revision identifiers, used by Alembic.
revision: str = "0005"
down_revision: str | Sequence[str] | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

ALL_SCOPES = "read,run,admin"
# Parents before children, so a rebuilt child's foreign keys name a table that exists.
TABLES = (
    "datasets",
    "run_groups",
    "base_maps",
    "runs",
    "map_versions",
    "run_metrics",
    "api_tokens",
)


def _rebuild_sqlite_tables(autoincrement: bool) -> None:
    if op.get_bind().dialect.name != "sqlite":
        return
    for table in TABLES:
        with op.batch_alter_table(
            table, recreate="always", table_kwargs={"sqlite_autoincrement": autoincrement}
        ):
            pass


def upgrade() -> None:
    with op.batch_alter_table("api_tokens", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column(
                "scopes",
                sa.String(length=64),
                nullable=False,
                server_default=sa.text(f"'{ALL_SCOPES}'"),
            )
        )
    # The default only fills the existing rows: a new token's scopes are always chosen.
    with op.batch_alter_table("api_tokens", schema=None) as batch_op:
        batch_op.alter_column("scopes", server_default=None)
    _rebuild_sqlite_tables(autoincrement=True)


def downgrade() -> None:
    _rebuild_sqlite_tables(autoincrement=False)
    with op.batch_alter_table("api_tokens", schema=None) as batch_op:
        batch_op.drop_column("scopes")
