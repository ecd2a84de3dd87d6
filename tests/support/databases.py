"""Fresh test databases: an empty SQLite file or a randomly named PostgreSQL database on the
local server (127.0.0.1:5432, trust auth, user postgres), dropped at the end of the session.
Shared by the test fixtures (tests/app/conftest.py) and ``scripts/bench_scaleout.py``.

A database is named ``mapwise_test_<worker>_<random>``: the pytest-xdist worker (``gw0``, …,
``main`` outside xdist) that created it, so parallel workers never share one and each drops
only its own."""

from __future__ import annotations

import os
import secrets

import psycopg

PG_ADMIN = "host=127.0.0.1 port=5432 user=postgres dbname=test"
PG_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/{name}"


class PostgresUnreachableError(RuntimeError):
    """The local PostgreSQL server does not answer."""


def pg_connect() -> psycopg.Connection:
    try:
        return psycopg.connect(PG_ADMIN, autocommit=True, connect_timeout=5)
    except psycopg.OperationalError as exc:
        raise PostgresUnreachableError(
            f"PostgreSQL is not reachable at 127.0.0.1:5432 ({exc}); start it with "
            "`bash scripts/system-deps.sh`"
        ) from exc


class PgDatabases:
    """Creates fresh PostgreSQL databases and drops them all at the end."""

    def __init__(self) -> None:
        self.names: list[str] = []

    def create(self) -> str:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        name = f"mapwise_test_{worker}_{secrets.token_hex(4)}"
        with pg_connect() as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        self.names.append(name)
        return PG_URL.format(name=name)

    def drop_all(self) -> None:
        if not self.names:
            return
        with pg_connect() as conn:
            for name in self.names:
                conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
