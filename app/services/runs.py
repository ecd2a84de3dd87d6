"""Runs: create, list, cancel, resume; their versions, series, cells and comparisons (exports:
:mod:`app.services.run_exports`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from sqlalchemy.orm import Session

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import BaseMapRepo, DatasetRepo, MetricRepo, RunRepo, VersionRepo
from app.domain import (
    RESUMABLE,
    MapVersion,
    Page,
    Run,
    RunStatus,
    Series,
    VersionSummary,
)
from app.errors import ConflictError, InvalidRequestError, NotFoundError
from app.io.decimate import minmax_decimate
from app.io.names import check_name
from app.runs.frames import StatusFrame
from app.services import calibration_runs as cal
from app.services.admission import GroupBudget, Limits
from app.services.run_clone import CloneRequest, request_of
from app.services.run_plan import RunRequest, plan_run


class Submitter(Protocol):
    def submit(self, run_id: int) -> None: ...

    def deliver_local(self, message: dict[str, Any]) -> None: ...


@dataclass(frozen=True, slots=True)
class GroupRef:
    """The sweep or batch a run belongs to, as a runs list shows it."""

    id: int
    kind: str
    name: str
    size: int


class RunService:
    def __init__(self, db: Database, settings: Settings, executor: Submitter | None) -> None:
        self.db = db
        self.settings = settings
        self.executor = executor

    def need_executor(self) -> None:
        """Refuse work before anything is stored when this server executes no runs."""
        if self.executor is None:
            raise ConflictError("this server does not execute runs", field=None)

    def submit(self, run_id: int) -> None:
        """Hand a stored run to the executor."""
        self.need_executor()
        assert self.executor is not None
        self.executor.submit(run_id)

    # -- lifecycle ----------------------------------------------------------------------------

    def create(self, request: RunRequest) -> Run:
        """Plan and store the run in one transaction, then hand it to the executor."""
        self.need_executor()
        linked = None
        if request.calibration is not None:  # the A2L is opened before the transaction
            linked = cal.link_for_request(self.db, self.settings, request.calibration)
        run = self._store(request, linked)
        self.submit(run.id)
        return run

    def _store(self, request: RunRequest, linked: cal.LinkedMap | None = None) -> Run:
        with self.db.write() as s:
            return self.store_in(s, request, linked=linked)

    def store_in(
        self,
        s: Session,
        request: RunRequest,
        *,
        group_id: int | None = None,
        params: dict[str, Any] | None = None,
        budget: GroupBudget | None = None,
        linked: cal.LinkedMap | None = None,
    ) -> Run:
        """Plan ``request`` and store it, queued, in the caller's transaction ``s`` (its
        predicted versions added to a group's ``budget``; its table linked to the A2L map
        ``linked``)."""
        dataset = DatasetRepo(s).get(request.dataset_id)
        base_map = None
        if request.base_map_id is not None:
            base_map = BaseMapRepo(s).get(request.base_map_id)
        plan = plan_run(
            request,
            dataset,
            base_map,
            version_fraction=self.settings.version_fraction,
            limits=Limits.from_settings(self.settings),
        )
        if budget is not None:
            budget.add(plan.prediction)
        table_spec = plan.table_spec
        if linked is not None:
            cal.check_table(linked.char, table_spec, plan.estimator)
            table_spec = {**(table_spec or {}), "calibration": linked.to_json()}
        return RunRepo(s).add(
            dataset_id=dataset.id,
            name=plan.name,
            estimator=plan.estimator,
            signals=plan.signals,
            table_spec=table_spec,
            config=plan.config,
            estimator_config=plan.estimator_config,
            produces_map=plan.produces_map,
            n_samples=plan.n_samples,
            base_map_id=request.base_map_id,
            group_id=group_id,
            params=params,
        )

    def get(self, run_id: int) -> Run:
        with self.db.read() as s:
            return RunRepo(s).get(run_id)

    def list(
        self,
        *,
        limit: int,
        offset: int,
        dataset_id: int | None,
        status: RunStatus | None,
        q: str | None = None,
        estimator: str | None = None,
        group_id: int | None = None,
        top_level: bool = False,
    ) -> Page[Run]:
        """A page of runs, newest first (filters: :meth:`RunRepo.list`)."""
        with self.db.read() as s:
            return RunRepo(s).list(
                limit=limit,
                offset=offset,
                dataset_id=dataset_id,
                status=status,
                q=q,
                estimator=estimator,
                group_id=group_id,
                top_level=top_level,
            )

    def groups_of(self, runs: list[Run]) -> dict[int, GroupRef]:
        """The sweep or batch of each grouped run in ``runs``, by group id."""
        ids = {r.group_id for r in runs if r.group_id is not None}
        with self.db.read() as s:
            repo = RunRepo(s)
            refs, sizes = repo.group_refs(ids), repo.group_sizes(ids)
        return {
            gid: GroupRef(gid, kind, name, sizes.get(gid, 0)) for gid, (kind, name) in refs.items()
        }

    # -- management ---------------------------------------------------------------------------

    def rename(self, run_id: int, name: str) -> Run:
        """Give the run a new name (422 naming ``name`` when blank or with control
        characters; the length is checked by the request model)."""
        clean = check_name(name, field="name", what="run name")
        if not clean:
            raise InvalidRequestError("a run name may not be empty", field="name")
        with self.db.write() as s:
            return RunRepo(s).rename(run_id, clean)

    def delete(self, run_id: int) -> int:
        """Delete a finished run with its versions, metrics and series; return how many
        versions went. A queued or running run is refused (409 naming its status): cancel
        it first, so deleting never silently stops work. A sweep's or batch's run may go
        (the group's counts are computed from its remaining runs); base maps promoted from
        the run keep their lineage, which is a record, not a reference."""
        with self.db.write() as s:
            return RunRepo(s).delete(run_id, unless=(RunStatus.QUEUED, RunStatus.RUNNING))

    def clone(self, run_id: int, overrides: CloneRequest | None = None) -> Run:
        """A new queued run like ``run_id`` (name "<name> (copy)"), with ``overrides``,
        validated and stored exactly as ``POST /api/runs`` would (:meth:`create`)."""
        return self.create(request_of(self.get(run_id), overrides))

    def cancel(self, run_id: int) -> Run:
        with self.db.write() as s:
            runs = RunRepo(s)
            run = runs.get(run_id)
            if run.finished:
                raise ConflictError(f"run {run_id} is already {run.status}", field="run_id")
            if run.status == RunStatus.QUEUED:
                runs.set_status(
                    run_id, RunStatus.CANCELLED, only_if=(RunStatus.QUEUED,), finished=True
                )
                cancelled_queued = True
            else:
                runs.request_stop(run_id, "cancel")
                cancelled_queued = False
        if cancelled_queued and self.executor is not None:
            self.executor.deliver_local(StatusFrame(run_id, RunStatus.CANCELLED).to_message())
        return self.get(run_id)

    def resume(self, run_id: int) -> Run:
        with self.db.write() as s:
            runs = RunRepo(s)
            run = runs.get(run_id)
            if run.status not in RESUMABLE:
                raise ConflictError(
                    f"only interrupted or cancelled runs resume; run {run_id} is {run.status}",
                    field="run_id",
                )
            runs.reset_for_resume(run_id)
        self.submit(run_id)
        if self.executor is not None:
            self.executor.deliver_local(StatusFrame(run_id, RunStatus.QUEUED).to_message())
        return self.get(run_id)

    # -- versions -------------------------------------------------------------------------------

    def versions(self, run_id: int, *, limit: int, offset: int) -> Page[VersionSummary]:
        with self.db.read() as s:
            RunRepo(s).get(run_id)
            return VersionRepo(s).list(run_id, limit=limit, offset=offset)

    def version(self, run_id: int, version_id: int) -> MapVersion:
        with self.db.read() as s:
            RunRepo(s).get(run_id)
            return VersionRepo(s).get(run_id, version_id)

    def version_by_number(self, run_id: int, number: int) -> MapVersion:
        """Version ``number`` (1…n by step) of the run, as URLs and exports name it."""
        with self.db.read() as s:
            RunRepo(s).get(run_id)
            return VersionRepo(s).by_number(run_id, number)

    def latest_version(self, run_id: int) -> MapVersion | None:
        with self.db.read() as s:
            RunRepo(s).get(run_id)
            return VersionRepo(s).latest(run_id)

    def label(self, run_id: int, version_id: int, label: str | None) -> VersionSummary:
        """Label a map version (``None`` clears it); 422 naming ``label`` for a control or
        formatting character, as for every name."""
        if label is not None:
            label = check_name(label, field="label", what="version label")
        with self.db.write() as s:
            return VersionRepo(s).set_label(run_id, version_id, label)

    # -- results --------------------------------------------------------------------------------

    def series(self, run_id: int, *, points: int) -> tuple[np.ndarray, list[Series]]:
        """The stored result series on their shared time base, at most ``points`` samples
        (REST ``/runs/{id}/series`` and the stream's full frame of a finished run)."""
        with self.db.read() as s:
            RunRepo(s).get(run_id)
            stored = MetricRepo(s).series(run_id)
        if not stored:
            return np.empty(0), []
        # Min/max per bucket, not a stride: a one-sample spike (an error's maximum) stays
        # visible however far the series is thinned.
        time, values = minmax_decimate(stored[0].time, {x.name: x.values for x in stored}, points)
        return time, [Series(x.name, x.unit, time, values[x.name], x.role) for x in stored]

    def cells(self, run_id: int) -> MapVersion | None:
        return self.latest_version(run_id)

    def compare(self, run_ids: list[int]) -> list[tuple[Run, MapVersion | None]]:
        if not run_ids:
            raise InvalidRequestError("give run ids as ?runs=1,2,3", field="runs")
        out = []
        with self.db.read() as s:
            for k, run_id in enumerate(run_ids):
                try:
                    run = RunRepo(s).get(run_id)
                except NotFoundError as exc:  # the query names it by its place in ?runs=
                    raise NotFoundError(exc.message, field=f"runs[{k}]") from None
                out.append((run, VersionRepo(s).latest(run_id)))
        return out
