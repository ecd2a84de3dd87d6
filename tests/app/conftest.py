"""Fixtures of the app tests: every service test runs on SQLite and on PostgreSQL.

Each backend gets a fresh database per test module, migrated from empty by the app's own
start-up, and one real app (TestClient: real ASGI app, lifespan, process pool). PostgreSQL
is the local server (127.0.0.1:5432, trust auth, user postgres); a database
``mapwise_test_<worker>_<random>`` is created for each module (``<worker>`` the pytest-xdist
worker, so parallel workers never share one) and dropped at the end of the session. SQLite
files live under pytest's temporary directory, which is per xdist worker too.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

warnings.filterwarnings("ignore", message=".*httpx.*starlette.testclient.*")

from fastapi.testclient import TestClient  # noqa: E402

from app.api import create_app  # noqa: E402
from tests.support.databases import PgDatabases  # noqa: E402
from tests.support.helpers import service_settings  # noqa: E402

# The PostgreSQL half carries the ``postgres`` marker, so ``-m "not postgres"`` keeps SQLite.
BACKENDS = ("sqlite", pytest.param("postgresql", marks=pytest.mark.postgres))


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
    return Path(__file__).resolve().parents[2] / "app" / "data" / "example_nox.csv"
