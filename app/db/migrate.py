"""Alembic from code: upgrade, the current and head revisions, and the schema check the
server makes at start-up (an out-of-date shared database is never migrated silently)."""

from __future__ import annotations

import fcntl
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import inspect, text
from sqlalchemy.engine import make_url

from app.db.engine import make_engine, normalise_url
from app.resources import resource_dir

MIGRATIONS_DIR = resource_dir("migrations")

SchemaState = Literal["empty", "current", "outdated", "unknown"]


def alembic_config(url: str, *, store_url: str | None = None) -> Config:
    """``store_url``: the artifact store the data migrations (0008) move datasets' samples
    to and from; ``None``: ``MAPWISE_STORE_URL``, else ``./mapwise-data/``."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    # ConfigParser interpolation: a literal % in a password must be doubled.
    config.set_main_option("sqlalchemy.url", normalise_url(url).replace("%", "%%"))
    config.attributes["store_url"] = store_url
    return config


def head_revision() -> str:
    heads = ScriptDirectory.from_config(alembic_config("sqlite://")).get_heads()
    if len(heads) != 1:
        raise RuntimeError(f"migrations must have exactly one head, found {heads}")
    return heads[0]


def current_revision(url: str) -> str | None:
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            return MigrationContext.configure(connection).get_current_revision()
    finally:
        engine.dispose()


MIGRATION_LOCK_KEY = 0x6D617077  # "mapw": the PostgreSQL advisory lock of migrations


def upgrade(url: str, revision: str = "head", *, store_url: str | None = None) -> None:
    """Migrate to ``revision``, one process at a time: two servers starting on an empty
    database, or ``mapwise db upgrade`` run twice, never migrate concurrently (the second
    waits, then finds the schema already there). ``store_url``: see :func:`alembic_config`."""
    with migration_lock(url):
        command.upgrade(alembic_config(url, store_url=store_url), revision)


@contextmanager
def migration_lock(url: str) -> Iterator[None]:
    """PostgreSQL: a session advisory lock; SQLite: an exclusive ``flock`` on a file beside
    the database (an in-memory database needs none)."""
    url = normalise_url(url)
    if url.startswith("postgresql"):
        engine = make_engine(url)
        try:
            with engine.connect() as connection:
                connection.execute(text("SELECT pg_advisory_lock(:k)"), {"k": MIGRATION_LOCK_KEY})
                connection.commit()
                try:
                    yield
                finally:
                    connection.execute(
                        text("SELECT pg_advisory_unlock(:k)"), {"k": MIGRATION_LOCK_KEY}
                    )
                    connection.commit()
        finally:
            engine.dispose()
        return
    database = make_url(url).database
    if not database or database == ":memory:":
        yield
        return
    with open(f"{database}.migrate-lock", "a+b") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@dataclass(frozen=True, slots=True)
class SchemaCheck:
    state: SchemaState
    current: str | None
    head: str

    @property
    def message(self) -> str:
        if self.state == "outdated":
            return (
                f"the database schema is at revision {self.current}, this mapwise needs "
                f"{self.head}; back it up and run `mapwise db upgrade`"
            )
        if self.state == "unknown":
            return (
                f"the database is at revision {self.current!r}, unknown to this mapwise "
                f"(head {self.head}); is it newer than this version?"
            )
        return f"schema {self.state} ({self.current})"


def migrate(
    url: str, *, store_url: str | None = None, only_if_empty: bool = False
) -> tuple[SchemaCheck, SchemaCheck]:
    """The schema's state, then, unless it is ``unknown`` (or, with ``only_if_empty``, not
    ``empty``), the upgrade to head: ``(before, after)``. Both are checked under the
    migration lock, so a migration another process runs is seen finished, never half-way:
    checked before taking the lock, a check whose two reads (the revision, then the tables)
    straddled that migration's commit saw tables without a revision, ``unknown``, and a
    second ``mapwise db upgrade`` on an empty PostgreSQL database failed."""
    with migration_lock(url):
        before = check_schema(url)
        if before.state == "unknown" or (only_if_empty and before.state != "empty"):
            return before, before
        command.upgrade(alembic_config(url, store_url=store_url), "head")
        return before, check_schema(url)


def check_schema(url: str) -> SchemaCheck:
    """``empty`` (no tables at all), ``current``, ``outdated`` or ``unknown`` (not ours)."""
    head = head_revision()
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            current = MigrationContext.configure(connection).get_current_revision()
            tables = set(inspect(connection).get_table_names()) - {"alembic_version"}
    finally:
        engine.dispose()
    if current is None:
        return SchemaCheck("empty" if not tables else "unknown", None, head)
    if current == head:
        return SchemaCheck("current", current, head)
    script = ScriptDirectory.from_config(alembic_config(url))
    known = {rev.revision for rev in script.walk_revisions()}
    return SchemaCheck("outdated" if current in known else "unknown", current, head)
