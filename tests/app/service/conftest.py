"""Fixtures of the service tests: every API test runs on SQLite and on PostgreSQL.

Each backend gets a fresh database per test module, migrated from empty by the app's own
start-up, and one real app (TestClient: real ASGI app, lifespan, process pool). PostgreSQL
is the local server (127.0.0.1:5432, trust auth, user postgres); a database
``mapwise_test_<random>`` is created for the session and dropped at its end.
"""

from __future__ import annotations

import secrets
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

warnings.filterwarnings("ignore", message=".*httpx.*starlette.testclient.*")

from fastapi.testclient import TestClient  # noqa: E402

from app.api import create_app  # noqa: E402
from tests.app.service.helpers import service_settings  # noqa: E402

PG_ADMIN = "host=127.0.0.1 port=5432 user=postgres dbname=test"
PG_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/{name}"
BACKENDS = ("sqlite", "postgresql")


def pg_connect():  # type: ignore[no-untyped-def]
    import psycopg

    try:
        return psycopg.connect(PG_ADMIN, autocommit=True, connect_timeout=5)
    except psycopg.OperationalError as exc:
        pytest.fail(
            f"PostgreSQL is not reachable at 127.0.0.1:5432 ({exc}); start it with "
            "`pg_ctlcluster --skip-systemctl-redirect $(ls /etc/postgresql) main start`"
        )


class PgDatabases:
    """Creates fresh PostgreSQL databases and drops them all at the end."""

    def __init__(self) -> None:
        self.names: list[str] = []

    def create(self) -> str:
        name = f"mapwise_test_{secrets.token_hex(4)}"
        with pg_connect() as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        self.names.append(name)
        return PG_URL.format(name=name)

    def drop_all(self) -> None:
        with pg_connect() as conn:
            for name in self.names:
                conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture(scope="session")
def pg_databases() -> Iterator[PgDatabases]:
    databases = PgDatabases()
    yield databases
    databases.drop_all()


@pytest.fixture(scope="session")
def fresh_url(pg_databases: PgDatabases, tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """A factory of empty databases of either backend: ``fresh_url("sqlite")``."""

    def make(backend: str) -> str:
        if backend == "sqlite":
            return f"sqlite:///{tmp_path_factory.mktemp('db') / 'mapwise.db'}"
        return pg_databases.create()

    return make


@pytest.fixture(scope="session", params=BACKENDS)
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture(scope="module")
def database_url(backend: str, fresh_url) -> str:  # type: ignore[no-untyped-def]
    return fresh_url(backend)


@pytest.fixture(scope="module")
def client(database_url: str) -> Iterator[TestClient]:
    """The real app on a fresh database of the backend for each test module (no state shared
    across modules), runs executed by its pool."""
    with TestClient(create_app(service_settings(database_url))) as c:
        yield c


@pytest.fixture
def example_csv() -> Path:
    return Path(__file__).resolve().parents[3] / "app" / "data" / "example_nox.csv"
