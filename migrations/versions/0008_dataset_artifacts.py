"""Datasets' samples move from the ``payload`` npz blob to the artifact store.

Each dataset's samples become one Parquet object in the store at ``MAPWISE_STORE_URL`` (the
URL the app's settings give, passed by ``app.db.migrate.upgrade``; else the environment's or
``./mapwise-data/``); the row keeps its key (``artifact``) and its SHA-256
(``content_sha256``), and ``payload`` becomes nullable, ``NULL`` once moved. The truth blob
stays in the row.

Nothing in the database changes until every dataset is in the store and verified: each
object is read back, its hash checked and its arrays compared with the npz's bit for bit.
Any mismatch (or a store that cannot be written) aborts the migration with the dataset and
key named; the objects it wrote are removed and every blob is still there.

The downgrade reads each object back (hash checked), puts the npz blob into ``payload`` again
and drops the two columns; the objects stay in the store (delete ``datasets/`` by hand).

The data steps use the app's own store code (:mod:`app.store`, :mod:`app.db.blobs`), so the
files they write are the ones the app reads.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-03
"""

from collections.abc import Sequence

import numpy as np
import sqlalchemy as sa
from alembic import context, op

from app.db import blobs
from app.store import (
    ArtifactError,
    ArtifactStore,
    delete_dataset,
    load_columns,
    open_store,
    save_staged,
    stage_columns,
)
from app.store.parquet_signals import Column

# revision identifiers, used by Alembic.
revision: str = "0008"
down_revision: str | Sequence[str] | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

DATASETS = sa.table(
    "datasets",
    sa.column("id", sa.Integer),
    sa.column("channels", sa.JSON),
    sa.column("payload", sa.LargeBinary),
    sa.column("artifact", sa.String),
    sa.column("content_sha256", sa.String),
)


class DataMigrationError(ArtifactError):
    """A dataset's samples did not survive the move; nothing was changed."""

    code = "artifact_migration"


def _store() -> ArtifactStore:
    return open_store(context.config.attributes.get("store_url"))


def upgrade() -> None:
    store = _store()
    moved = _move_payloads(store)
    try:
        with op.batch_alter_table(
            "datasets", schema=None, table_kwargs={"sqlite_autoincrement": True}
        ) as batch_op:
            batch_op.add_column(sa.Column("artifact", sa.String(length=200), nullable=True))
            batch_op.add_column(sa.Column("content_sha256", sa.String(length=64), nullable=True))
            batch_op.alter_column("payload", existing_type=sa.LargeBinary(), nullable=True)
        bind = op.get_bind()
        for dataset_id, (key, sha256) in moved.items():
            bind.execute(
                DATASETS.update()
                .where(DATASETS.c.id == dataset_id)
                .values(artifact=key, content_sha256=sha256, payload=None)
            )
    except BaseException:
        _remove(store, moved)
        raise


def _move_payloads(store: ArtifactStore) -> dict[int, tuple[str, str]]:
    """Every payload into the store and verified, one dataset at a time; ``id → (key,
    sha256)``. On any failure the objects written so far are removed."""
    bind = op.get_bind()
    ids = bind.scalars(
        sa.select(DATASETS.c.id).where(DATASETS.c.payload.is_not(None)).order_by(DATASETS.c.id)
    ).all()
    moved: dict[int, tuple[str, str]] = {}
    try:
        for dataset_id in ids:
            channels, payload = bind.execute(
                sa.select(DATASETS.c.channels, DATASETS.c.payload).where(
                    DATASETS.c.id == dataset_id
                )
            ).one()
            try:
                moved[dataset_id] = _move_one(store, dataset_id, channels, payload)
            except DataMigrationError:
                raise
            except Exception as exc:  # an unreadable blob, an unwritable store
                raise DataMigrationError(
                    f"dataset {dataset_id}: its samples cannot be moved to the store "
                    f"{store.location('')}, nothing was changed: {type(exc).__name__}: {exc}"
                ) from exc
    except BaseException:
        _remove(store, moved)
        raise
    return moved


def _move_one(
    store: ArtifactStore, dataset_id: int, channels: list[dict], payload: bytes
) -> tuple[str, str]:
    arrays = blobs.unpack(payload)
    time = arrays["time"]
    columns = [
        Column(c["name"], c.get("unit", ""), arrays[f"c{i}"]) for i, c in enumerate(channels)
    ]
    with stage_columns(store, time, columns) as staged:
        key = save_staged(store, dataset_id, staged)
    try:
        back_time, back = load_columns(store, dataset_id, key, staged.sha256)
        expected = [("time", "s", time)] + [(c.name, c.unit, c.values) for c in columns]
        actual = [("time", "s", back_time)] + [(c.name, c.unit, c.values) for c in back]
        if len(actual) != len(expected):
            raise DataMigrationError(f"{len(back)} channels read back, {len(columns)} written")
        for (name, unit, want), (got_name, got_unit, got) in zip(expected, actual, strict=True):
            if (name, unit) != (got_name, got_unit) or not _identical(want, got):
                raise DataMigrationError(f"channel {name!r} did not read back bit for bit")
    except Exception as exc:
        delete_dataset(store, dataset_id, key)
        raise DataMigrationError(
            f"dataset {dataset_id}: moving its samples to {store.location(key)} failed, "
            f"nothing was changed: {exc}"
        ) from exc
    return key, staged.sha256


def _identical(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _remove(store: ArtifactStore, moved: dict[int, tuple[str, str]]) -> None:
    for dataset_id, (key, _) in moved.items():
        delete_dataset(store, dataset_id, key)


def downgrade() -> None:
    store = _store()
    bind = op.get_bind()
    rows = bind.execute(
        sa.select(DATASETS.c.id, DATASETS.c.artifact, DATASETS.c.content_sha256)
        .where(DATASETS.c.artifact.is_not(None))
        .order_by(DATASETS.c.id)
    ).all()
    for dataset_id, key, sha256 in rows:
        time, columns = load_columns(store, dataset_id, key, sha256)
        arrays = {"time": time} | {f"c{i}": c.values for i, c in enumerate(columns)}
        bind.execute(
            DATASETS.update().where(DATASETS.c.id == dataset_id).values(payload=blobs.pack(arrays))
        )
    with op.batch_alter_table(
        "datasets", schema=None, table_kwargs={"sqlite_autoincrement": True}
    ) as batch_op:
        batch_op.alter_column("payload", existing_type=sa.LargeBinary(), nullable=False)
        batch_op.drop_column("content_sha256")
        batch_op.drop_column("artifact")
