"""Runs: their rows, the attempt protocol (claim, fence, heartbeat, lost attempts) and
status changes."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from datetime import datetime
from typing import Any

from sqlalchemy import delete, func, or_, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.db.models import MapVersionRow, RunGroupRow, RunMetricRow, RunRow, utcnow
from app.db.repositories.base import from_row, valid_id
from app.domain import Page, Run, RunStatus
from app.errors import ConflictError, NotFoundError, SupersededError


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
            status=RunStatus.QUEUED,
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
        return from_row(
            Run,
            row,
            status=RunStatus(row.status),
            signals=dict(row.signals),
            table=row.table_spec,
            config=dict(row.config),
            estimator_config=dict(row.estimator_config),
            rejected={k: int(v) for k, v in (row.rejected or {}).items()},
            metrics=metrics,
            n_versions=n_versions,
        )

    def _row(self, run_id: int) -> RunRow:
        row = self.s.get(RunRow, run_id, populate_existing=True) if valid_id(run_id) else None
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
        q: str | None = None,
        estimator: str | None = None,
        group_id: int | None = None,
        top_level: bool = False,
    ) -> Page[Run]:
        """Runs newest first, filtered. ``q``: the name contains it (case-insensitive);
        ``group_id``: the runs of that sweep or batch. ``top_level``: the runs outside any
        group, and each group once, as its first run matching the other filters (so a list
        pages over ungrouped runs and groups together, a group placed by its first run)."""
        where: list[Any] = []
        if dataset_id is not None:
            where.append(RunRow.dataset_id == dataset_id)
        if status is not None:
            where.append(RunRow.status == status)
        if q:
            where.append(func.lower(RunRow.name).contains(q.lower(), autoescape=True))
        if estimator is not None:
            where.append(RunRow.estimator == estimator)
        if group_id is not None:
            where.append(RunRow.group_id == group_id)
        if top_level:
            firsts = (
                select(func.min(RunRow.id))
                .where(RunRow.group_id.is_not(None), *where)
                .group_by(RunRow.group_id)
            )
            where.append(or_(RunRow.group_id.is_(None), RunRow.id.in_(firsts)))
        total = self.s.scalar(select(func.count()).select_from(RunRow).where(*where)) or 0
        rows = list(
            self.s.scalars(
                select(RunRow).where(*where).order_by(RunRow.id.desc()).limit(limit).offset(offset)
            )
        )
        ids = [r.id for r in rows]
        metrics, counts = self._metrics(ids), self._n_versions(ids)
        return Page([self._run(r, metrics[r.id], counts[r.id]) for r in rows], total, limit, offset)

    def rename(self, run_id: int, name: str) -> Run:
        self._row(run_id).name = name
        self.s.flush()
        return self.get(run_id)

    def delete(self, run_id: int, *, unless: tuple[str, ...]) -> int:
        """Delete the run with its versions and metrics; return how many versions went.
        The row is locked first (PostgreSQL), so an executor cannot claim it meanwhile;
        :class:`ConflictError` naming the status when the run is in one of ``unless``."""
        row = (
            self.s.scalars(select(RunRow).where(RunRow.id == run_id).with_for_update()).first()
            if valid_id(run_id)
            else None
        )
        if row is None:
            raise NotFoundError(f"run {run_id} does not exist", field="run_id")
        if row.status in unless:
            raise ConflictError(
                f"run {run_id} is {row.status}; cancel it first (POST /api/runs/{run_id}/cancel), "
                "then delete it",
                field="run_id",
            )
        n_versions = self._n_versions([run_id])[run_id]
        self.s.execute(delete(RunMetricRow).where(RunMetricRow.run_id == run_id))
        self.s.execute(delete(MapVersionRow).where(MapVersionRow.run_id == run_id))
        self.s.execute(delete(RunRow).where(RunRow.id == run_id))
        return n_versions

    def group_refs(self, group_ids: Collection[int]) -> dict[int, tuple[str, str]]:
        """``{group id: (kind, name)}`` of the given sweeps and batches."""
        if not group_ids:
            return {}
        q = select(RunGroupRow.id, RunGroupRow.kind, RunGroupRow.name).where(
            RunGroupRow.id.in_(list(group_ids))
        )
        return {gid: (kind, name) for gid, kind, name in self.s.execute(q)}

    def group_sizes(self, group_ids: Collection[int]) -> dict[int, int]:
        """``{group id: number of runs}`` (all of them, whatever a list filtered)."""
        if not group_ids:
            return {}
        q = (
            select(RunRow.group_id, func.count())
            .where(RunRow.group_id.in_(list(group_ids)))
            .group_by(RunRow.group_id)
        )
        return {int(gid): int(n) for gid, n in self.s.execute(q)}

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
        self, run_id: int, *, owner: str, statuses: tuple[str, ...] = (RunStatus.QUEUED,)
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
                status=RunStatus.RUNNING,
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
            .where(
                RunRow.id == run_id, RunRow.attempt == attempt, RunRow.status == RunStatus.RUNNING
            )
            .values(heartbeat_at=utcnow())
        )
        if result.rowcount != 1:  # type: ignore[attr-defined]
            raise SupersededError(f"run {run_id}: attempt {attempt} is no longer the live one")

    def stale_running(self, *, stale_before: datetime) -> list[Run]:
        """Runs ``running`` whose attempt has not heartbeated since ``stale_before``
        (including an attempt that died before its first heartbeat)."""
        q = select(RunRow).where(
            RunRow.status == RunStatus.RUNNING,
            func.coalesce(RunRow.heartbeat_at, RunRow.started_at) < stale_before,
        )
        return [self._run(row, {}, 0) for row in self.s.scalars(q)]

    def running_owned_by(self, owners: Collection[str]) -> list[int]:
        if not owners:
            return []
        q = select(RunRow.id).where(
            RunRow.status == RunStatus.RUNNING, RunRow.owner.in_(list(owners))
        )
        return list(self.s.scalars(q.order_by(RunRow.id)))

    def running_owners(self) -> list[str]:
        q = select(RunRow.owner).where(RunRow.status == RunStatus.RUNNING).distinct()
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
                status=RunStatus.QUEUED,
                error=None,
                finished_at=None,
                stop_request=None,
                lost_attempts=0,
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
            .where(RunRow.id == run_id, RunRow.status.in_((RunStatus.QUEUED, RunStatus.RUNNING)))
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
        q = select(RunRow).where(RunRow.id == run_id, RunRow.status == RunStatus.RUNNING)
        if attempt is not None:
            q = q.where(RunRow.attempt == attempt)
        row = self.s.scalars(q.with_for_update()).first()
        if row is None:
            return None
        row.lost_attempts += 1
        row.stop_request = None
        if row.lost_attempts >= max_lost:
            row.status, row.finished_at = RunStatus.FAILED, utcnow()
            row.error = f"{reason}; given up after {row.lost_attempts} lost attempts"
        elif requeue:
            row.status, row.error = RunStatus.QUEUED, None
        else:
            row.status, row.error = RunStatus.INTERRUPTED, f"{reason}; resume the run"
        self.s.flush()
        return row.status

    def interrupt(self, run_ids: Collection[int], message: str) -> list[int]:
        """``running`` runs among ``run_ids`` become ``interrupted`` (resumable)."""
        ids = list(run_ids)
        if not ids:
            return []
        q = select(RunRow.id).where(RunRow.id.in_(ids), RunRow.status == RunStatus.RUNNING)
        hit = list(self.s.scalars(q))
        if hit:
            self.s.execute(
                update(RunRow)
                .where(RunRow.id.in_(hit))
                .values(status=RunStatus.INTERRUPTED, error=message, stop_request=None)
            )
        return hit
