"""Alembic: one head; an empty database upgraded step by step has exactly the models' schema
(MLflow's drift test), on SQLite and PostgreSQL; downgrade and upgrade again work."""

from __future__ import annotations

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory

from app.db.engine import make_engine
from app.db.migrate import alembic_config, check_schema, current_revision, head_revision, upgrade
from app.db.models import Base


def _drift(url: str) -> list:
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            context = MigrationContext.configure(connection, opts={"compare_type": True})
            return compare_metadata(context, Base.metadata)
    finally:
        engine.dispose()


def test_one_head() -> None:
    script = ScriptDirectory.from_config(alembic_config("sqlite://"))
    assert script.get_heads() == [head_revision()]
    assert head_revision() == "0004"


def test_upgraded_empty_database_matches_the_models(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    url = fresh_url(backend)
    assert check_schema(url).state == "empty"
    upgrade(url, "0001")
    check = check_schema(url)
    assert (check.state, check.current) == ("outdated", "0001")
    assert "mapwise db upgrade" in check.message
    assert _drift(url) != []  # 0001 alone lacks base maps and tokens: the test can fail
    upgrade(url)
    assert current_revision(url) == head_revision()
    assert check_schema(url).state == "current"
    assert _drift(url) == []


def test_downgrade_to_base_and_upgrade_again(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    url = fresh_url(backend)
    upgrade(url)
    command.downgrade(alembic_config(url), "base")
    assert check_schema(url).state == "empty"
    upgrade(url)
    assert _drift(url) == []
