"""SQLAlchemy 2 models: the schema Alembic migrations must produce exactly.

Arrays live in ``LargeBinary`` columns as ``.npz`` (:mod:`app.db.blobs`); payload columns
are deferred so lists never load them. Every SQLite table is ``AUTOINCREMENT``: an id is never
reused after a delete, so an old link never shows other data (PostgreSQL sequences never
reuse either). Only :mod:`app.db.repositories` touches these classes.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)
    type_annotation_map = {dict[str, Any]: JSON, list[Any]: JSON}  # noqa: RUF012


class DatasetRow(Base):
    """A log or simulation: channel list and time base; its samples are the Parquet object
    ``artifact`` in the artifact store (:mod:`app.store`), whose SHA-256 is ``content_sha256``.

    ``payload``: the npz samples of a row from before revision 0008 (``NULL`` since: the
    migration moves them to the store). ``channels``: ``[{"name", "unit"}]``, plus
    ``"masked": n`` on a channel with ``n > 0`` masked samples and, in a dataset stored as
    recorded, ``"timing": [start_s, stop_s, step_s]``; ``notes``: what ingest said about the
    upload (``NULL``: nothing).
    """

    __tablename__ = "datasets"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    source: Mapped[str] = mapped_column(String(64))
    rows: Mapped[int] = mapped_column(Integer)
    rate_hz: Mapped[float] = mapped_column(Float)
    duration_s: Mapped[float] = mapped_column(Float)
    time_column: Mapped[str] = mapped_column(String(200))
    channels: Mapped[list[Any]] = mapped_column(JSON)
    notes: Mapped[list[str] | None] = mapped_column(JSON)
    scenario: Mapped[str | None] = mapped_column(String(64))
    seed: Mapped[int | None] = mapped_column(Integer)
    payload: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    artifact: Mapped[str | None] = mapped_column(String(200))
    content_sha256: Mapped[str | None] = mapped_column(String(64))
    truth: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class RunRow(Base):
    """One estimator session over a dataset; ``stop_request`` is how a worker is told to stop."""

    __tablename__ = "runs"
    __table_args__ = (
        Index("ix_runs_dataset_status", "dataset_id", "status"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    dataset_id: Mapped[int] = mapped_column(ForeignKey("datasets.id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(200))
    estimator: Mapped[str] = mapped_column(String(64))
    status: Mapped[str] = mapped_column(String(16), index=True)
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    sample: Mapped[int] = mapped_column(Integer, default=0)
    n_samples: Mapped[int] = mapped_column(Integer, default=0)
    error: Mapped[str | None] = mapped_column(Text)
    signals: Mapped[dict[str, Any]] = mapped_column(JSON)
    table_spec: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    config: Mapped[dict[str, Any]] = mapped_column(JSON)
    estimator_config: Mapped[dict[str, Any]] = mapped_column(JSON)
    rejected: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    produces_map: Mapped[bool] = mapped_column(Boolean)
    base_map_id: Mapped[int | None] = mapped_column(ForeignKey("base_maps.id", ondelete="SET NULL"))
    stop_request: Mapped[str | None] = mapped_column(String(16))
    # Each execution is an attempt: claim() increments the number and every write of the
    # attempt checks it (fencing); the heartbeat tells the sweep whether the attempt lives.
    attempt: Mapped[int] = mapped_column(Integer, default=0, server_default=text("0"))
    heartbeat_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    owner: Mapped[str | None] = mapped_column(String(200))  # executor of the attempt
    lost_attempts: Mapped[int] = mapped_column(Integer, default=0, server_default=text("0"))
    group_id: Mapped[int | None] = mapped_column(
        ForeignKey("run_groups.id", ondelete="SET NULL"), index=True
    )
    params: Mapped[dict[str, Any] | None] = mapped_column(JSON)  # a sweep's sampled values
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))


class RunGroupRow(Base):
    """A sweep (``kind="sweep"``: one dataset, sampled parameters, ranked by ``metric``) or a
    fleet batch (``kind="batch"``: many datasets, one config); ``request`` is what was asked."""

    __tablename__ = "run_groups"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    name: Mapped[str] = mapped_column(String(200))
    estimator: Mapped[str] = mapped_column(String(64))
    request: Mapped[dict[str, Any]] = mapped_column(JSON)
    metric: Mapped[str | None] = mapped_column(String(100))
    order: Mapped[str | None] = mapped_column(String(8))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class MapVersionRow(Base):
    """A persisted point of a run: the map (if any), its variances and visits, the
    estimator state it resumes from, and the output series since the previous version."""

    __tablename__ = "map_versions"
    __table_args__ = (
        UniqueConstraint("run_id", "step", name="uq_map_versions_run_step"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    step: Mapped[int] = mapped_column(Integer)
    time_s: Mapped[float] = mapped_column(Float)
    label: Mapped[str | None] = mapped_column(String(200))
    final: Mapped[bool] = mapped_column(Boolean, default=False)
    axes: Mapped[list[Any] | None] = mapped_column(JSON)
    values: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    variances: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    visits: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    cell_rejections: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    state: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    segment: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    rejected: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class RunMetricRow(Base):
    """A final metric of a run (``value``) or a downsampled result series (``series``)."""

    __tablename__ = "run_metrics"
    __table_args__ = (
        UniqueConstraint("run_id", "name", name="uq_run_metrics_run_name"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(100))
    unit: Mapped[str] = mapped_column(String(50), default="")
    value: Mapped[float | None] = mapped_column(Float)
    series: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)


class BaseMapRow(Base):
    """A named starting map, promoted from a run version or imported, with its lineage."""

    __tablename__ = "base_maps"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    source: Mapped[str] = mapped_column(String(32))
    axes: Mapped[list[Any]] = mapped_column(JSON)
    values: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
    # Lineage is a record, not a reference: it survives the deletion of its run or dataset.
    run_id: Mapped[int | None] = mapped_column(Integer)
    version_id: Mapped[int | None] = mapped_column(Integer)
    dataset_id: Mapped[int | None] = mapped_column(Integer)
    estimator: Mapped[str | None] = mapped_column(String(64))
    config: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    parent_base_map_id: Mapped[int | None] = mapped_column(
        ForeignKey("base_maps.id", ondelete="SET NULL")
    )
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ApiTokenRow(Base):
    """A bearer token, stored only as its SHA-256 hash."""

    __tablename__ = "api_tokens"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    prefix: Mapped[str] = mapped_column(String(16))
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    last_used_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    revoked_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    scopes: Mapped[str] = mapped_column(String(64))  # comma-separated: read,run,admin


class EcuRow(Base):
    """An ECU: its A2L and current values (HEX, S19, DCM or CDFX) as uploaded, the A2L's
    hash (the key of the parse cache) and its number of characteristics."""

    __tablename__ = "ecus"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    a2l_sha256: Mapped[str] = mapped_column(String(64))
    a2l: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
    characteristics: Mapped[int] = mapped_column(Integer)
    values_format: Mapped[str | None] = mapped_column(String(8))
    values: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
