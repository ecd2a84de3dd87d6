"""Repositories: the only code that touches SQLAlchemy. They take a session, return domain
objects (:mod:`app.domain`) and never commit; the caller's unit of work does."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from datetime import UTC, datetime
from typing import Any

import numpy as np
from sqlalchemy import delete, func, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, undefer

from app.db import blobs
from app.db.models import (
    ApiTokenRow,
    BaseMapRow,
    DatasetRow,
    MapVersionRow,
    RunGroupRow,
    RunMetricRow,
    RunRow,
    utcnow,
)
from app.domain import (
    ApiToken,
    BaseMap,
    Channel,
    Dataset,
    MapVersion,
    Page,
    ResumePoint,
    Run,
    RunGroup,
    Series,
    VersionSummary,
)
from app.errors import ConflictError, NotFoundError, SupersededError

MAX_ID = 2**31 - 1


def _valid(id_: int) -> bool:
    """Ids beyond the databases' INTEGER cannot exist (and would overflow the driver)."""
    return 1 <= id_ <= MAX_ID


def aware(t: datetime | None) -> datetime | None:
    """SQLite returns naive datetimes; everything we store is UTC."""
    if t is None:
        return None
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


# --- datasets ------------------------------------------------------------------------------


def _dataset(row: DatasetRow, has_truth: bool) -> Dataset:
    return Dataset(
        id=row.id,
        name=row.name,
        source=row.source,
        rows=row.rows,
        rate_hz=row.rate_hz,
        duration_s=row.duration_s,
        time_column=row.time_column,
        channels=[Channel(c["name"], c.get("unit", "")) for c in row.channels],
        scenario=row.scenario,
        seed=row.seed,
        has_truth=has_truth,
        created_at=aware(row.created_at),  # type: ignore[arg-type]
    )


class DatasetRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def add(
        self,
        *,
        name: str,
        source: str,
        rows: int,
        rate_hz: float,
        duration_s: float,
        time_column: str,
        channels: list[Channel],
        payload: bytes,
        scenario: str | None = None,
        seed: int | None = None,
        truth: bytes | None = None,
    ) -> Dataset:
        row = DatasetRow(
            name=name,
            source=source,
            rows=rows,
            rate_hz=rate_hz,
            duration_s=duration_s,
            time_column=time_column,
            channels=[{"name": c.name, "unit": c.unit} for c in channels],
            scenario=scenario,
            seed=seed,
            payload=payload,
            truth=truth,
        )
        self.s.add(row)
        self.s.flush()
        return _dataset(row, truth is not None)

    def _row(self, dataset_id: int) -> DatasetRow:
        row = self.s.get(DatasetRow, dataset_id) if _valid(dataset_id) else None
        if row is None:
            raise NotFoundError(f"dataset {dataset_id} does not exist", field="dataset_id")
        return row

    def get(self, dataset_id: int) -> Dataset:
        row = self._row(dataset_id)
        return _dataset(row, self._has_truth(dataset_id))

    def _has_truth(self, dataset_id: int) -> bool:
        q = select(DatasetRow.truth.is_not(None)).where(DatasetRow.id == dataset_id)
        return bool(self.s.scalar(q))

    def list(self, *, limit: int, offset: int) -> Page[Dataset]:
        total = self.s.scalar(select(func.count()).select_from(DatasetRow)) or 0
        q = (
            select(DatasetRow, DatasetRow.truth.is_not(None))
            .order_by(DatasetRow.id.desc())
            .limit(limit)
            .offset(offset)
        )
        items = [_dataset(row, bool(t)) for row, t in self.s.execute(q)]
        return Page(items, total, limit, offset)

    def payload(self, dataset_id: int) -> bytes:
        blob = self.s.scalar(select(DatasetRow.payload).where(DatasetRow.id == dataset_id))
        if blob is None:
            raise NotFoundError(f"dataset {dataset_id} does not exist", field="dataset_id")
        return blob

    def truth(self, dataset_id: int) -> bytes | None:
        return self.s.scalar(select(DatasetRow.truth).where(DatasetRow.id == dataset_id))

    def run_count(self, dataset_id: int) -> int:
        q = select(func.count()).select_from(RunRow).where(RunRow.dataset_id == dataset_id)
        return self.s.scalar(q) or 0

    def delete(self, dataset_id: int) -> None:
        self._row(dataset_id)
        run_ids = select(RunRow.id).where(RunRow.dataset_id == dataset_id)
        self.s.execute(delete(RunMetricRow).where(RunMetricRow.run_id.in_(run_ids)))
        self.s.execute(delete(MapVersionRow).where(MapVersionRow.run_id.in_(run_ids)))
        self.s.execute(delete(RunRow).where(RunRow.dataset_id == dataset_id))
        self.s.execute(delete(DatasetRow).where(DatasetRow.id == dataset_id))


# --- runs ----------------------------------------------------------------------------------


class RunRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def add(
        self,
        *,
        dataset_id: int,
        name: str,
        estimator: str,
        signals: dict[str, str],
        table_spec: dict[str, Any] | None,
        config: dict[str, Any],
        estimator_config: dict[str, Any],
        produces_map: bool,
        n_samples: int,
        base_map_id: int | None,
        group_id: int | None = None,
        params: dict[str, Any] | None = None,
    ) -> Run:
        row = RunRow(
            dataset_id=dataset_id,
            name=name,
            estimator=estimator,
            status="queued",
            progress=0.0,
            sample=0,
            n_samples=n_samples,
            signals=signals,
            table_spec=table_spec,
            config=config,
            estimator_config=estimator_config,
            rejected={},
            produces_map=produces_map,
            base_map_id=base_map_id,
            group_id=group_id,
            params=params,
        )
        self.s.add(row)
        try:
            self.s.flush()
        except IntegrityError:  # the dataset or base map was deleted by a concurrent request
            raise ConflictError(
                f"dataset {dataset_id} or base map {base_map_id} was deleted meanwhile",
                field="dataset_id",
            ) from None
        return self._run(row, {}, 0)

    def _run(self, row: RunRow, metrics: dict[str, float | None], n_versions: int) -> Run:
        return Run(
            id=row.id,
            dataset_id=row.dataset_id,
            name=row.name,
            estimator=row.estimator,
            status=row.status,
            progress=row.progress,
            sample=row.sample,
            n_samples=row.n_samples,
            error=row.error,
            signals=dict(row.signals),
            table=row.table_spec,
            config=dict(row.config),
            estimator_config=dict(row.estimator_config),
            rejected={k: int(v) for k, v in (row.rejected or {}).items()},
            produces_map=row.produces_map,
            base_map_id=row.base_map_id,
            stop_request=row.stop_request,
            attempt=row.attempt,
            lost_attempts=row.lost_attempts,
            owner=row.owner,
            heartbeat_at=aware(row.heartbeat_at),
            created_at=aware(row.created_at),  # type: ignore[arg-type]
            started_at=aware(row.started_at),
            finished_at=aware(row.finished_at),
            metrics=metrics,
            n_versions=n_versions,
            group_id=row.group_id,
            params=row.params,
        )

    def _row(self, run_id: int) -> RunRow:
        row = self.s.get(RunRow, run_id, populate_existing=True) if _valid(run_id) else None
        if row is None:
            raise NotFoundError(f"run {run_id} does not exist", field="run_id")
        return row

    def get(self, run_id: int) -> Run:
        row = self._row(run_id)
        return self._run(row, self._metrics([run_id])[run_id], self._n_versions([run_id])[run_id])

    def list(
        self,
        *,
        limit: int,
        offset: int,
        dataset_id: int | None = None,
        status: str | None = None,
    ) -> Page[Run]:
        where = []
        if dataset_id is not None:
            where.append(RunRow.dataset_id == dataset_id)
        if status is not None:
            where.append(RunRow.status == status)
        total = self.s.scalar(select(func.count()).select_from(RunRow).where(*where)) or 0
        rows = list(
            self.s.scalars(
                select(RunRow).where(*where).order_by(RunRow.id.desc()).limit(limit).offset(offset)
            )
        )
        ids = [r.id for r in rows]
        metrics, counts = self._metrics(ids), self._n_versions(ids)
        return Page([self._run(r, metrics[r.id], counts[r.id]) for r in rows], total, limit, offset)

    def in_group(self, group_id: int) -> list[Run]:
        """The group's runs in creation order, with their final metrics."""
        rows = list(
            self.s.scalars(select(RunRow).where(RunRow.group_id == group_id).order_by(RunRow.id))
        )
        ids = [r.id for r in rows]
        metrics, versions = self._metrics(ids), self._n_versions(ids)
        return [self._run(r, metrics[r.id], versions[r.id]) for r in rows]

    def _metrics(self, run_ids: list[int]) -> dict[int, dict[str, float | None]]:
        out: dict[int, dict[str, float | None]] = {i: {} for i in run_ids}
        if run_ids:
            q = select(RunMetricRow.run_id, RunMetricRow.name, RunMetricRow.value).where(
                RunMetricRow.run_id.in_(run_ids), RunMetricRow.series.is_(None)
            )
            for run_id, name, value in self.s.execute(q):
                out[run_id][name] = value
        return out

    def _n_versions(self, run_ids: list[int]) -> dict[int, int]:
        out = dict.fromkeys(run_ids, 0)
        if run_ids:
            q = (
                select(MapVersionRow.run_id, func.count())
                .where(MapVersionRow.run_id.in_(run_ids))
                .group_by(MapVersionRow.run_id)
            )
            out.update({run_id: int(n) for run_id, n in self.s.execute(q)})
        return out

    def claim(
        self, run_id: int, *, owner: str, statuses: tuple[str, ...] = ("queued",)
    ) -> int | None:
        """Start a new attempt: move the run from one of ``statuses`` to ``running`` with the
        next attempt number, which is returned; ``None`` if the run was not in ``statuses``.
        Claiming a ``running`` run supersedes its attempt (a Dask retry after its worker was
        lost): the old attempt's next fenced write fails, so it can never overwrite."""
        now = utcnow()
        result = self.s.execute(
            update(RunRow)
            .where(RunRow.id == run_id, RunRow.status.in_(statuses))
            .values(
                status="running",
                started_at=now,
                heartbeat_at=now,
                owner=owner,
                attempt=RunRow.attempt + 1,
                stop_request=None,
                error=None,
            )
        )
        if result.rowcount != 1:  # type: ignore[attr-defined]
            return None
        return int(self.s.scalar(select(RunRow.attempt).where(RunRow.id == run_id)) or 0)

    def fence(self, run_id: int, attempt: int) -> None:
        """Check, inside the caller's transaction, that ``attempt`` is still the run's live
        attempt, and record a heartbeat; raise :class:`SupersededError` otherwise. On
        PostgreSQL the update locks the row until commit, so a concurrent claim waits for
        this transaction and then sees its writes."""
        result = self.s.execute(
            update(RunRow)
            .where(RunRow.id == run_id, RunRow.attempt == attempt, RunRow.status == "running")
            .values(heartbeat_at=utcnow())
        )
        if result.rowcount != 1:  # type: ignore[attr-defined]
            raise SupersededError(f"run {run_id}: attempt {attempt} is no longer the live one")

    def stale_running(self, *, stale_before: datetime) -> list[Run]:
        """Runs ``running`` whose attempt has not heartbeated since ``stale_before``
        (including an attempt that died before its first heartbeat)."""
        q = select(RunRow).where(
            RunRow.status == "running",
            func.coalesce(RunRow.heartbeat_at, RunRow.started_at) < stale_before,
        )
        return [self._run(row, {}, 0) for row in self.s.scalars(q)]

    def running_owned_by(self, owners: Collection[str]) -> list[int]:
        if not owners:
            return []
        q = select(RunRow.id).where(RunRow.status == "running", RunRow.owner.in_(list(owners)))
        return list(self.s.scalars(q.order_by(RunRow.id)))

    def running_owners(self) -> list[str]:
        q = select(RunRow.owner).where(RunRow.status == "running").distinct()
        return [o for o in self.s.scalars(q) if o]

    def set_status(
        self,
        run_id: int,
        status: str,
        *,
        only_if: tuple[str, ...] | None = None,
        error: str | None = None,
        finished: bool = False,
    ) -> bool:
        values: dict[str, Any] = {"status": status, "error": error, "stop_request": None}
        if finished:
            values["finished_at"] = utcnow()
        stmt = update(RunRow).where(RunRow.id == run_id)
        if only_if is not None:
            stmt = stmt.where(RunRow.status.in_(only_if))
        return self.s.execute(stmt.values(**values)).rowcount == 1  # type: ignore[attr-defined]

    def reset_for_resume(self, run_id: int) -> None:
        """Queued again by a user's resume: the count of lost attempts starts afresh."""
        self.s.execute(
            update(RunRow)
            .where(RunRow.id == run_id)
            .values(
                status="queued", error=None, finished_at=None, stop_request=None, lost_attempts=0
            )
        )

    def progress(
        self, run_id: int, *, sample: int, progress: float, rejected: Mapping[str, int]
    ) -> None:
        self.s.execute(
            update(RunRow)
            .where(RunRow.id == run_id)
            .values(sample=sample, progress=progress, rejected=dict(rejected))
        )

    def request_stop(self, run_id: int, kind: str) -> None:
        self.s.execute(
            update(RunRow)
            .where(RunRow.id == run_id, RunRow.status.in_(("queued", "running")))
            .values(stop_request=kind)
        )

    def stop_request(self, run_id: int) -> str | None:
        return self.s.scalar(select(RunRow.stop_request).where(RunRow.id == run_id))

    def ids_with_status(self, status: str) -> list[int]:
        q = select(RunRow.id).where(RunRow.status == status).order_by(RunRow.id)
        return list(self.s.scalars(q))

    def lose_attempt(
        self, run_id: int, *, reason: str, requeue: bool, max_lost: int, attempt: int | None = None
    ) -> str | None:
        """The live attempt of a ``running`` run died (its worker was killed, ran out of
        memory, or stopped heartbeating). The run is re-queued (``requeue``) or
        ``interrupted`` (resumable); after ``max_lost`` lost attempts it is ``failed`` with
        the reason, so a poison run is never redelivered forever. Returns the new status,
        or ``None`` when the run was not running (or ``attempt`` is no longer its own)."""
        q = select(RunRow).where(RunRow.id == run_id, RunRow.status == "running")
        if attempt is not None:
            q = q.where(RunRow.attempt == attempt)
        row = self.s.scalars(q.with_for_update()).first()
        if row is None:
            return None
        row.lost_attempts += 1
        row.stop_request = None
        if row.lost_attempts >= max_lost:
            row.status, row.finished_at = "failed", utcnow()
            row.error = f"{reason}; given up after {row.lost_attempts} lost attempts"
        elif requeue:
            row.status, row.error = "queued", None
        else:
            row.status, row.error = "interrupted", f"{reason}; resume the run"
        self.s.flush()
        return row.status

    def interrupt(self, run_ids: Collection[int], message: str) -> list[int]:
        """``running`` runs among ``run_ids`` become ``interrupted`` (resumable)."""
        ids = list(run_ids)
        if not ids:
            return []
        q = select(RunRow.id).where(RunRow.id.in_(ids), RunRow.status == "running")
        hit = list(self.s.scalars(q))
        if hit:
            self.s.execute(
                update(RunRow)
                .where(RunRow.id.in_(hit))
                .values(status="interrupted", error=message, stop_request=None)
            )
        return hit


class GroupRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    @staticmethod
    def _group(row: RunGroupRow) -> RunGroup:
        return RunGroup(
            id=row.id,
            kind=row.kind,
            name=row.name,
            estimator=row.estimator,
            request=dict(row.request),
            metric=row.metric,
            order=row.order,
            created_at=aware(row.created_at),  # type: ignore[arg-type]
        )

    def add(
        self,
        *,
        kind: str,
        name: str,
        estimator: str,
        request: dict[str, Any],
        metric: str | None = None,
        order: str | None = None,
    ) -> RunGroup:
        row = RunGroupRow(
            kind=kind, name=name, estimator=estimator, request=request, metric=metric, order=order
        )
        self.s.add(row)
        self.s.flush()
        return self._group(row)

    def get(self, group_id: int, kind: str) -> RunGroup:
        row = self.s.get(RunGroupRow, group_id) if _valid(group_id) else None
        if row is None or row.kind != kind:
            raise NotFoundError(f"{kind} {group_id} does not exist", field=f"{kind}_id")
        return self._group(row)

    def list(self, kind: str, *, limit: int, offset: int) -> Page[RunGroup]:
        where = RunGroupRow.kind == kind
        total = self.s.scalar(select(func.count()).select_from(RunGroupRow).where(where)) or 0
        q = select(RunGroupRow).where(where).order_by(RunGroupRow.id.desc())
        rows = self.s.scalars(q.limit(limit).offset(offset))
        return Page([self._group(r) for r in rows], total, limit, offset)


# --- map versions and results ----------------------------------------------------------------


def _summary(row: MapVersionRow) -> VersionSummary:
    return VersionSummary(
        id=row.id,
        run_id=row.run_id,
        step=row.step,
        time_s=row.time_s,
        label=row.label,
        final=row.final,
        created_at=aware(row.created_at),  # type: ignore[arg-type]
    )


def _unpack_dict(blob: bytes | None) -> dict[str, np.ndarray]:
    return {} if blob is None else blobs.unpack(blob)


class VersionRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def add(
        self,
        *,
        run_id: int,
        step: int,
        time_s: float,
        final: bool,
        axes: list[dict[str, Any]] | None,
        values: np.ndarray | None,
        variances: np.ndarray | None,
        visits: np.ndarray | None,
        cell_rejections: Mapping[str, np.ndarray],
        state: bytes | None,
        segment: Mapping[str, np.ndarray] | None,
        rejected: Mapping[str, int],
        label: str | None = None,
    ) -> VersionSummary:
        row = MapVersionRow(
            run_id=run_id,
            step=step,
            time_s=time_s,
            final=final,
            label=label,
            axes=axes,
            values=None if values is None else blobs.pack_array(values),
            variances=None if variances is None else blobs.pack_array(variances),
            visits=None if visits is None else blobs.pack_array(visits),
            cell_rejections=blobs.pack(cell_rejections) if cell_rejections else None,
            state=state,
            segment=None if segment is None else blobs.pack(segment),
            rejected={k: int(v) for k, v in rejected.items()},
        )
        self.s.add(row)
        self.s.flush()
        return _summary(row)

    def list(self, run_id: int, *, limit: int, offset: int) -> Page[VersionSummary]:
        where = MapVersionRow.run_id == run_id
        total = self.s.scalar(select(func.count()).select_from(MapVersionRow).where(where)) or 0
        q = (
            select(MapVersionRow)
            .where(where)
            .order_by(MapVersionRow.step, MapVersionRow.id)
            .limit(limit)
            .offset(offset)
        )
        return Page([_summary(r) for r in self.s.scalars(q)], total, limit, offset)

    def _full(self, where: Any, order: Any = None) -> MapVersion | None:
        q = (
            select(MapVersionRow)
            .options(
                undefer(MapVersionRow.values),
                undefer(MapVersionRow.variances),
                undefer(MapVersionRow.visits),
                undefer(MapVersionRow.cell_rejections),
            )
            .where(*where)
        )
        if order is not None:
            q = q.order_by(order).limit(1)
        row = self.s.scalars(q).first()
        if row is None:
            return None
        return MapVersion(
            summary=_summary(row),
            axes=row.axes,
            values=blobs.unpack_array(row.values),
            variances=blobs.unpack_array(row.variances),
            visits=blobs.unpack_array(row.visits),
            cell_rejections=_unpack_dict(row.cell_rejections),
            rejected={k: int(v) for k, v in (row.rejected or {}).items()},
        )

    def get(self, run_id: int, version_id: int) -> MapVersion:
        found = self._full([MapVersionRow.run_id == run_id, MapVersionRow.id == version_id])
        if found is None:
            raise NotFoundError(f"run {run_id} has no version {version_id}", field="version_id")
        return found

    def latest(self, run_id: int) -> MapVersion | None:
        """The final version, else the last one persisted."""
        return self._full(
            [MapVersionRow.run_id == run_id],
            order=(MapVersionRow.step.desc()),
        )

    def set_label(self, run_id: int, version_id: int, label: str | None) -> VersionSummary:
        row = self.s.get(MapVersionRow, version_id)
        if row is None or row.run_id != run_id:
            raise NotFoundError(f"run {run_id} has no version {version_id}", field="version_id")
        row.label = label
        self.s.flush()
        return _summary(row)

    def resume_point(self, run_id: int) -> ResumePoint | None:
        """The last version with a state, plus every earlier version's output segment."""
        q = (
            select(MapVersionRow)
            .options(
                undefer(MapVersionRow.state),
                undefer(MapVersionRow.visits),
                undefer(MapVersionRow.cell_rejections),
            )
            .where(MapVersionRow.run_id == run_id, MapVersionRow.state.is_not(None))
            .order_by(MapVersionRow.step.desc())
            .limit(1)
        )
        row = self.s.scalars(q).first()
        if row is None or row.state is None:
            return None
        segments_q = (
            select(MapVersionRow.segment)
            .where(MapVersionRow.run_id == run_id, MapVersionRow.step <= row.step)
            .order_by(MapVersionRow.step)
        )
        segments = [blobs.unpack(b) for b in self.s.scalars(segments_q) if b is not None]
        return ResumePoint(
            version_id=row.id,
            step=row.step,
            state=blobs.unpack_state(row.state),
            visits=blobs.unpack_array(row.visits),
            cell_rejections=_unpack_dict(row.cell_rejections),
            segments=segments,
        )

    def segments(self, run_id: int) -> list[dict[str, np.ndarray]]:
        """Every version's output segment, in order (together: the run's per-sample outputs)."""
        q = (
            select(MapVersionRow.segment)
            .where(MapVersionRow.run_id == run_id)
            .order_by(MapVersionRow.step)
        )
        return [blobs.unpack(b) for b in self.s.scalars(q) if b is not None]

    def records(self, run_id: int) -> list[MapVersion]:
        """Every version with its arrays, in order."""
        q = select(MapVersionRow.id).where(MapVersionRow.run_id == run_id)
        ids = list(self.s.scalars(q.order_by(MapVersionRow.step)))
        return [self.get(run_id, i) for i in ids]

    def has_step(self, run_id: int, step: int) -> bool:
        q = select(MapVersionRow.id).where(
            MapVersionRow.run_id == run_id, MapVersionRow.step == step
        )
        return self.s.scalar(q.limit(1)) is not None

    def delete_after(self, run_id: int, step: int) -> None:
        self.s.execute(
            delete(MapVersionRow).where(MapVersionRow.run_id == run_id, MapVersionRow.step > step)
        )


class MetricRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def replace(
        self, run_id: int, values: Mapping[str, float | None], series: list[Series]
    ) -> None:
        self.s.execute(delete(RunMetricRow).where(RunMetricRow.run_id == run_id))
        for name, value in values.items():
            self.s.add(RunMetricRow(run_id=run_id, name=name, unit="", value=value))
        for item in series:
            blob = blobs.pack({"time": item.time, "values": item.values})
            self.s.add(
                RunMetricRow(run_id=run_id, name=f"series:{item.name}", unit=item.unit, series=blob)
            )
        self.s.flush()

    def series(self, run_id: int) -> list[Series]:
        q = (
            select(RunMetricRow)
            .options(undefer(RunMetricRow.series))
            .where(RunMetricRow.run_id == run_id, RunMetricRow.series.is_not(None))
            .order_by(RunMetricRow.id)
        )
        out = []
        for row in self.s.scalars(q):
            arrays = blobs.unpack(row.series)  # type: ignore[arg-type]
            out.append(
                Series(row.name.removeprefix("series:"), row.unit, arrays["time"], arrays["values"])
            )
        return out


# --- base maps -----------------------------------------------------------------------------


class BaseMapRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    @staticmethod
    def _map(row: BaseMapRow) -> BaseMap:
        values = blobs.unpack_array(row.values)
        assert values is not None
        return BaseMap(
            id=row.id,
            name=row.name,
            source=row.source,
            axes=list(row.axes),
            values=values,
            run_id=row.run_id,
            version_id=row.version_id,
            dataset_id=row.dataset_id,
            estimator=row.estimator,
            config=row.config,
            parent_base_map_id=row.parent_base_map_id,
            metrics=dict(row.metrics or {}),
            created_at=aware(row.created_at),  # type: ignore[arg-type]
        )

    def add(
        self,
        *,
        name: str,
        source: str,
        axes: list[dict[str, Any]],
        values: np.ndarray,
        run_id: int | None = None,
        version_id: int | None = None,
        dataset_id: int | None = None,
        estimator: str | None = None,
        config: dict[str, Any] | None = None,
        parent_base_map_id: int | None = None,
        metrics: dict[str, Any] | None = None,
    ) -> BaseMap:
        row = BaseMapRow(
            name=name,
            source=source,
            axes=axes,
            values=blobs.pack_array(np.asarray(values, dtype=np.float64)),
            run_id=run_id,
            version_id=version_id,
            dataset_id=dataset_id,
            estimator=estimator,
            config=config,
            parent_base_map_id=parent_base_map_id,
            metrics=metrics or {},
        )
        self.s.add(row)
        self.s.flush()
        return self._map(row)

    def get(self, base_map_id: int) -> BaseMap:
        q = (
            select(BaseMapRow)
            .options(undefer(BaseMapRow.values))
            .where(BaseMapRow.id == base_map_id)
        )
        row = self.s.scalars(q).first()
        if row is None:
            raise NotFoundError(f"base map {base_map_id} does not exist", field="base_map_id")
        return self._map(row)

    def list(self, *, limit: int, offset: int) -> Page[BaseMap]:
        total = self.s.scalar(select(func.count()).select_from(BaseMapRow)) or 0
        q = (
            select(BaseMapRow)
            .options(undefer(BaseMapRow.values))
            .order_by(BaseMapRow.id.desc())
            .limit(limit)
            .offset(offset)
        )
        return Page([self._map(r) for r in self.s.scalars(q)], total, limit, offset)


# --- API tokens ----------------------------------------------------------------------------


def _token(row: ApiTokenRow) -> ApiToken:
    return ApiToken(
        id=row.id,
        name=row.name,
        prefix=row.prefix,
        created_at=aware(row.created_at),  # type: ignore[arg-type]
        last_used_at=aware(row.last_used_at),
        revoked_at=aware(row.revoked_at),
    )


class TokenRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def add(self, *, name: str, prefix: str, token_hash: str) -> ApiToken:
        row = ApiTokenRow(name=name, prefix=prefix, token_hash=token_hash)
        self.s.add(row)
        self.s.flush()
        return _token(row)

    def list(self) -> list[ApiToken]:
        return [_token(r) for r in self.s.scalars(select(ApiTokenRow).order_by(ApiTokenRow.id))]

    def revoke(self, token_id: int) -> ApiToken:
        row = self.s.get(ApiTokenRow, token_id)
        if row is None:
            raise NotFoundError(f"token {token_id} does not exist", field="token_id")
        if row.revoked_at is None:
            row.revoked_at = utcnow()
        self.s.flush()
        return _token(row)

    def active_by_hash(self, token_hash: str) -> ApiToken | None:
        q = select(ApiTokenRow).where(
            ApiTokenRow.token_hash == token_hash, ApiTokenRow.revoked_at.is_(None)
        )
        row = self.s.scalars(q).first()
        return None if row is None else _token(row)

    def touch(self, token_id: int) -> None:
        self.s.execute(
            update(ApiTokenRow).where(ApiTokenRow.id == token_id).values(last_used_at=utcnow())
        )
