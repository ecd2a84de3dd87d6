"""Engines and units of work for SQLite and PostgreSQL.

SQLite gets WAL (readers never wait for the writer), a busy timeout, enforced foreign keys,
and ``BEGIN IMMEDIATE`` for write transactions: a deferred transaction that reads and then
writes fails at once with "database is locked" when another process wrote in between,
whatever the timeout. PostgreSQL gets ``pool_pre_ping`` so a restarted server is survived,
and its read units of work run at REPEATABLE READ: every statement of one sees the same
snapshot, as on SQLite (a list's total and its items agree).

Each SQLite connection's private page cache is held to ``SQLITE_CACHE_KIB``. SQLite's
default (2 MiB a connection) filled, page by page, as the database grew under the soak, so
the API process, with up to 15 pooled connections, grew by up to 30 MB over half an hour
(+11 %); the operating system's page cache already holds the file, and read latencies did
not change with a 64 KiB cache (the soak: docs/benchmarks.md#load).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, Literal

from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import InterfaceError, OperationalError
from sqlalchemy.orm import Session, sessionmaker

from app.errors import DatabaseUnavailableError

SQLITE_BUSY_TIMEOUT_MS = 30_000
SQLITE_CACHE_KIB = 256
_WRITE = "mapwise_write"


def normalise_url(url: str) -> str:
    """``postgresql://`` and ``postgres://`` use psycopg 3 (the installed driver)."""
    for prefix in ("postgresql://", "postgres://"):
        if url.startswith(prefix):
            return "postgresql+psycopg://" + url[len(prefix) :]
    return url


def make_engine(url: str) -> Engine:
    url = normalise_url(url)
    if url.startswith("sqlite"):
        engine = create_engine(
            url,
            connect_args={"timeout": SQLITE_BUSY_TIMEOUT_MS / 1000, "check_same_thread": False},
        )
        _sqlite_pragmas(engine)
        return engine
    return create_engine(url, pool_pre_ping=True, pool_size=5, max_overflow=10)


def _sqlite_pragmas(engine: Engine) -> None:
    memory = make_url(engine.url).database in (None, "", ":memory:")

    @event.listens_for(engine, "connect")
    def _connect(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None  # we emit BEGIN ourselves (below)
        cursor = dbapi_connection.cursor()
        if not memory:
            cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.execute(f"PRAGMA cache_size=-{SQLITE_CACHE_KIB}")  # negative: KiB, not pages
        cursor.close()

    @event.listens_for(engine, "begin")
    def _begin(conn: Any) -> None:
        write = conn.get_execution_options().get(_WRITE, False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")


class Database:
    """One engine and its read and write units of work.

    ``with db.write() as s:`` commits at the end (or rolls back on error);
    ``with db.read() as s:`` never writes. Repositories never commit.
    """

    def __init__(self, url: str) -> None:
        self.url = normalise_url(url)
        self.engine = make_engine(self.url)
        # One snapshot for a read unit of work, so a page's total and its items agree: SQLite's
        # deferred BEGIN gives it; PostgreSQL's default READ COMMITTED takes a snapshot per
        # statement (a read-only REPEATABLE READ transaction never fails to serialise).
        reads = self.engine
        if self.backend == "postgresql":
            reads = self.engine.execution_options(isolation_level="REPEATABLE READ")
        self._read = sessionmaker(bind=reads, expire_on_commit=False)
        self._write = sessionmaker(
            bind=self.engine.execution_options(**{_WRITE: True}), expire_on_commit=False
        )

    @property
    def shared(self) -> bool:
        """Whether another process can open this database (not SQLite in memory)."""
        return not (
            self.backend == "sqlite" and make_url(self.url).database in (None, "", ":memory:")
        )

    @property
    def backend(self) -> Literal["sqlite", "postgresql"]:
        return "sqlite" if self.url.startswith("sqlite") else "postgresql"

    @contextmanager
    def write(self) -> Iterator[Session]:
        with _available(), self._write.begin() as session:
            yield session

    @contextmanager
    def read(self) -> Iterator[Session]:
        with _available(), self._read() as session:
            yield session

    def ping(self) -> None:
        """A round trip to the database (raises when it is unreachable)."""
        with self.read() as session:
            session.execute(text("SELECT 1"))

    def dispose(self) -> None:
        self.engine.dispose()


@contextmanager
def _available() -> Iterator[None]:
    """Connection-level failures (a restarting PostgreSQL, a locked SQLite beyond its busy
    timeout) become :class:`DatabaseUnavailableError`: a 503 to clients, a retry to workers.
    ``pool_pre_ping`` then replaces the dead connections on the next checkout."""
    try:
        yield
    except (OperationalError, InterfaceError) as exc:
        reason = str(getattr(exc, "orig", None) or exc).strip().splitlines()[0][:200]
        raise DatabaseUnavailableError(f"the database is unavailable: {reason}") from exc
