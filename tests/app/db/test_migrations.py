"""Alembic: one head; an empty database upgraded step by step has exactly the models' schema
(MLflow's drift test), on SQLite and PostgreSQL; downgrade and upgrade again work."""

from __future__ import annotations

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import text

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
    assert head_revision() == "0008"


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


def test_concurrent_upgrades_are_serialised(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    """Three `mapwise db upgrade` at once on an empty database: one migrates, the others wait
    for its lock and find the schema there; all succeed, the schema is exactly the models'."""
    import subprocess
    import sys
    from pathlib import Path

    url = fresh_url(backend)
    root = Path(__file__).resolve().parents[3]
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "app.cli", "db", "upgrade", "--database-url", url],
            cwd=root,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(3)
    ]
    results = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], results
    assert current_revision(url) == head_revision()
    assert _drift(url) == []


def test_data_survives_upgrade_downgrade_upgrade_from_the_previous_schema(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
) -> None:
    """Rows written at the previous revision are unchanged after upgrade → downgrade →
    upgrade (SQLite batch mode rebuilds tables; PostgreSQL alters them). The dataset's
    samples leave ``payload`` for the artifact store (0008) and come back bit for bit."""
    from datetime import UTC, datetime

    import numpy as np
    from sqlalchemy import MetaData, select

    from app.db import blobs

    url = fresh_url(backend)
    script = ScriptDirectory.from_config(alembic_config(url))
    previous = script.get_revision(head_revision()).down_revision
    assert isinstance(previous, str)
    upgrade(url, previous)
    engine = make_engine(url)
    names = ("datasets", "runs", "map_versions")
    blob, now = bytes(range(256)), datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
    samples = {"time": np.array([0.0, 0.1, 0.2]), "c0": np.array([1.5, -0.0, 3e-300])}
    try:
        meta = MetaData()
        meta.reflect(engine, only=names)
        with engine.begin() as connection:
            connection.execute(
                meta.tables["datasets"].insert(),
                {"id": 7, "name": "log", "source": "csv", "rows": 3, "rate_hz": 10.0,
                 "duration_s": 0.2, "time_column": "time", "channels": [{"name": "y"}],
                 "payload": blobs.pack(samples), "created_at": now},
            )  # fmt: skip
            connection.execute(
                meta.tables["runs"].insert(),
                {"id": 11, "dataset_id": 7, "name": "r", "estimator": "skf",
                 "status": "succeeded", "progress": 1.0, "sample": 3, "n_samples": 3,
                 "signals": {"y": "y"}, "config": {"p0": 1}, "estimator_config": {},
                 "rejected": {"mask": 0}, "produces_map": True, "created_at": now},
            )  # fmt: skip
            connection.execute(
                meta.tables["map_versions"].insert(),
                {"id": 5, "run_id": 11, "step": 3, "time_s": 0.2, "final": True,
                 "values": blob, "rejected": {}, "created_at": now},
            )  # fmt: skip

        def snapshot() -> dict[str, list[tuple]]:
            with engine.connect() as connection:
                return {
                    n: [tuple(r) for r in connection.execute(select(*_columns(meta, n)))]
                    for n in names
                }

        def payload() -> dict[str, np.ndarray]:
            with engine.connect() as connection:
                stored = connection.execute(select(meta.tables["datasets"].c.payload)).scalar()
            return blobs.unpack(stored)

        before = snapshot()
        assert all(len(rows) == 1 for rows in before.values())
        upgrade(url)
        command.downgrade(alembic_config(url), previous)
        assert {k: v.tobytes() for k, v in payload().items()} == {
            k: v.tobytes() for k, v in samples.items()
        }
        upgrade(url)
        assert snapshot() == before
        assert current_revision(url) == head_revision()
        assert _drift(url) == []
    finally:
        engine.dispose()


def _columns(meta, table: str) -> list:  # type: ignore[no-untyped-def]
    """The table's columns but the dataset's ``payload`` (in the artifact store since 0008)."""
    return [c for c in meta.tables[table].c if (table, c.name) != ("datasets", "payload")]


def test_tokens_from_before_scopes_get_every_scope(backend: str, fresh_url) -> None:  # type: ignore[no-untyped-def]
    """A token created at 0004 keeps working for everything after the upgrade."""
    from datetime import UTC, datetime

    from app.db.engine import Database
    from app.services.tokens import TokenService, hash_token

    url = fresh_url(backend)
    upgrade(url, "0004")
    engine = make_engine(url)
    try:
        with engine.begin() as connection:
            connection.execute(
                text(
                    "INSERT INTO api_tokens (name, prefix, token_hash, created_at) "
                    "VALUES ('old', 'mw_old', :h, :t)"
                ),
                {"h": hash_token("mw_old-secret"), "t": datetime(2026, 1, 1, tzinfo=UTC)},
            )
    finally:
        engine.dispose()
    upgrade(url)
    db = Database(url)
    try:
        token = TokenService(db).verify("mw_old-secret")
        assert token is not None
        assert token.scopes == ("read", "run", "admin")
        fresh, _ = TokenService(db).create("new")
        assert fresh.scopes == ("read", "run")
    finally:
        db.dispose()


def test_sqlite_never_reuses_an_id_after_a_delete(fresh_url) -> None:  # type: ignore[no-untyped-def]
    """create, delete, create: the new row's id is larger (an old link never shows other
    data), for every table, on a database upgraded from the previous revision."""
    url = fresh_url("sqlite")
    upgrade(url, "0004")
    upgrade(url)
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            rows = connection.execute(text("SELECT name, sql FROM sqlite_master"))
            sql = {name: create for name, create in rows}
        for table in Base.metadata.tables:
            assert "AUTOINCREMENT" in sql[table], table
        with engine.begin() as connection:
            insert = (
                "INSERT INTO run_groups (kind, name, estimator, request, created_at) "
                "VALUES ('sweep', 'g', 'skf', '{}', '2026-01-01')"
            )
            first = connection.execute(text(insert)).lastrowid
            second = connection.execute(text(insert)).lastrowid
            connection.execute(text("DELETE FROM run_groups WHERE id = :i"), {"i": second})
            third = connection.execute(text(insert)).lastrowid
        assert first < second < third
    finally:
        engine.dispose()


def test_ids_are_not_reused_through_the_api(client) -> None:  # type: ignore[no-untyped-def]
    """Through the service on either backend: a deleted dataset's id is never given out
    again."""
    body = {"scenario": "skf-sim1", "seed": 1, "duration_s": 2.0}
    ids = []
    for _ in range(2):
        response = client.post("/api/datasets/simulate", json=body)
        assert response.status_code == 201, response.text
        ids.append(response.json()["id"])
    assert client.delete(f"/api/datasets/{ids[1]}").status_code == 204
    response = client.post("/api/datasets/simulate", json=body)
    assert response.status_code == 201
    assert response.json()["id"] > ids[1]


def test_0006_adds_the_ecus_table_and_its_downgrade_drops_only_it(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
) -> None:
    from sqlalchemy import inspect

    url = fresh_url(backend)
    upgrade(url, "0005")

    def tables() -> set[str]:
        engine = make_engine(url)
        try:
            return set(inspect(engine).get_table_names()) - {"alembic_version"}
        finally:
            engine.dispose()

    before = tables()
    assert "ecus" not in before
    upgrade(url, "0006")
    assert tables() == before | {"ecus"}
    engine = make_engine(url)
    try:
        columns = {c["name"] for c in inspect(engine).get_columns("ecus")}
    finally:
        engine.dispose()
    assert columns == {
        "id", "name", "a2l_sha256", "a2l", "characteristics", "values_format", "values",
        "created_at",
    }  # fmt: skip
    command.downgrade(alembic_config(url), "0005")
    assert tables() == before


def test_0007_adds_dataset_notes_and_older_datasets_have_none(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
) -> None:
    """A dataset stored before 0007 reads as having nothing to say (``notes`` NULL); the
    downgrade drops only that column and keeps the row."""
    from datetime import UTC, datetime

    from sqlalchemy import MetaData, inspect, select

    url = fresh_url(backend)
    upgrade(url, "0006")
    engine = make_engine(url)
    try:
        meta = MetaData()
        meta.reflect(engine, only=["datasets"])
        with engine.begin() as connection:
            connection.execute(
                meta.tables["datasets"].insert(),
                {"id": 3, "name": "old", "source": "csv", "rows": 2, "rate_hz": 1.0,
                 "duration_s": 1.0, "time_column": "time", "channels": [{"name": "y"}],
                 "payload": b"npz", "created_at": datetime(2026, 1, 2, tzinfo=UTC)},
            )  # fmt: skip
        before = {c["name"] for c in inspect(engine).get_columns("datasets")}
        engine.dispose()
        upgrade(url, "0007")
        assert {c["name"] for c in inspect(engine).get_columns("datasets")} == before | {"notes"}
        with engine.connect() as connection:
            row = connection.execute(text("SELECT name, notes FROM datasets")).one()
        assert tuple(row) == ("old", None)
        engine.dispose()
        command.downgrade(alembic_config(url), "0006")
        assert {c["name"] for c in inspect(engine).get_columns("datasets")} == before
        with engine.connect() as connection:
            names = connection.execute(select(meta.tables["datasets"].c.name)).scalars().all()
        assert names == ["old"]
    finally:
        engine.dispose()
