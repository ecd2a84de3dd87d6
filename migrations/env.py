"""Alembic environment for mapwise (SQLite and PostgreSQL).

The URL comes from the caller (``app.db.migrate`` sets ``sqlalchemy.url``), else from
``MAPWISE_DATABASE_URL``. ``render_as_batch`` lets SQLite alter tables by copy-and-move, with
foreign keys off while it does (else the copy's drop cascades) and checked afterwards.
"""

from __future__ import annotations

from typing import Any

from alembic import context

from app.config import Settings
from app.db.engine import make_engine, normalise_url
from app.db.models import Base

config = context.config
target_metadata = Base.metadata


def _url() -> str:
    url = config.get_main_option("sqlalchemy.url")
    return normalise_url(url or Settings().database_url)


def run_offline() -> None:
    context.configure(
        url=_url(),
        target_metadata=target_metadata,
        literal_binds=True,
        render_as_batch=True,
        dialect_opts={"paramstyle": "named"},
    )
    with context.begin_transaction():
        context.run_migrations()


def run_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _run(connection)
        return
    engine = make_engine(_url())
    try:
        with engine.connect() as connection:
            sqlite = connection.dialect.name == "sqlite"
            if sqlite:
                # Batch mode rebuilds a table by copy, drop and rename: with foreign keys on,
                # dropping the old ``runs`` would cascade into ``map_versions`` and delete
                # every version. The pragma only takes effect outside a transaction, so it
                # goes straight to the driver before SQLAlchemy begins one.
                connection.connection.driver_connection.execute("PRAGMA foreign_keys=OFF")
            _run(connection)
            if sqlite:
                _check_foreign_keys(connection.connection.driver_connection)
    finally:
        engine.dispose()


def _check_foreign_keys(sqlite_connection: Any) -> None:
    """After the rebuild, every reference must still resolve (what the pragma skipped)."""
    broken = sqlite_connection.execute("PRAGMA foreign_key_check").fetchall()
    if broken:
        raise RuntimeError(f"the migration left dangling foreign keys: {broken[:5]}")


def _run(connection: object) -> None:
    context.configure(
        connection=connection,  # type: ignore[arg-type]
        target_metadata=target_metadata,
        render_as_batch=True,
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


if context.is_offline_mode():
    run_offline()
else:
    run_online()
