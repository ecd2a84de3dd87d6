"""Runs: create, list, cancel, resume; their versions, series, cells, exports and comparisons."""

from __future__ import annotations

import re
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
    SeriesRole,
    VersionSummary,
)
from app.errors import ConflictError, InvalidRequestError
from app.io.decimate import minmax_decimate
from app.io.errors import InputError
from app.io.map_json import map_document
from app.io.names import check_name
from app.runs.frames import StatusFrame
from app.services import calibration_runs as cal
from app.services.admission import GroupBudget, Limits
from app.services.run_clone import CloneRequest, request_of
from app.services.run_plan import RunRequest, plan_run
from app.store import load_signals, open_store
from estimation.estimator import Snapshot
from estimation.signals import Signals
from estimation.table import Axis, Table

EXPORT_FORMATS = ("json", "csv", "mcap", "dcm", "cdfx", "image")


class Submitter(Protocol):
    def submit(self, run_id: int) -> None: ...

    def deliver_local(self, message: dict[str, Any]) -> None: ...


@dataclass(frozen=True, slots=True)
class Download:
    content: bytes
    media_type: str
    filename: str


@dataclass(frozen=True, slots=True)
class GroupRef:
    """The sweep or batch a run belongs to, as a runs list shows it."""

    id: int
    kind: str
    name: str
    size: int


def table_of(version: MapVersion) -> Table:
    if version.axes is None or version.values is None:
        raise ConflictError("this run has no map", field="format")
    return Table([Axis.from_dict(a) for a in version.axes], version.values)


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "map"


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
            for run_id in run_ids:
                out.append((RunRepo(s).get(run_id), VersionRepo(s).latest(run_id)))
        return out

    # -- export ---------------------------------------------------------------------------------

    def export(
        self,
        run_id: int,
        *,
        fmt: str,
        version_id: int | None,
        part: str | None,
        number: int | None = None,
    ) -> Download:
        """The run (or one version: ``version_id`` the database id, or ``number`` its place
        1…n in the run; neither: the final or latest) as a file. Map files are named
        ``run<R>-<estimator>-v<N>`` and a DCM header says "run R …, version N"."""
        if fmt not in EXPORT_FORMATS:
            raise InvalidRequestError(
                f"format must be one of {', '.join(EXPORT_FORMATS)}, got {fmt!r}", field="format"
            )
        if version_id is not None and number is not None:
            raise InvalidRequestError(
                "give the version by id (version) or by number (number), not both",
                field="number",
            )
        with self.db.read() as s:
            run = RunRepo(s).get(run_id)
            versions = VersionRepo(s)
            if version_id is not None:
                version = versions.get(run_id, version_id)
            elif number is not None:
                version = versions.by_number(run_id, number)
            else:
                version = versions.latest(run_id)
        stem = _safe_name(f"run{run.id}-{run.estimator}")
        if fmt == "mcap":
            return Download(self._mcap(run), "application/octet-stream", f"{stem}.mcap")
        if fmt == "csv" and (part == "series" or (part is None and not run.produces_map)):
            return Download(self._series_csv(run), "text/csv; charset=utf-8", f"{stem}-series.csv")
        if part not in (None, "map"):
            raise InvalidRequestError("part must be 'map' or 'series'", field="part")
        if version is None:
            raise ConflictError(f"run {run_id} has no map version yet", field="version")
        stem = f"{stem}-v{version.summary.number}"
        required = fmt in cal.CALIBRATION_FORMATS
        linked = None
        if fmt != "csv":  # a CSV grid is the same with or without a link
            linked = cal.linked_run(self.db, self.settings, run.table, required=required)
        if linked is None and required:
            raise ConflictError(
                f"run {run_id} is not linked to an A2L map; format={fmt} needs a run created "
                "with calibration: {ecu_id, map}",
                field="format",
            )
        if fmt == "json":
            document = self._map_document(run, version)
            if linked is not None:
                try:
                    document |= cal.json_extras(linked.char, table_of(version), linked.to_json())
                except InputError as exc:  # e.g. a non-finite cell: the map itself still exports
                    document["calibration"] = linked.to_json() | {"error": exc.message}
            return Download(_json_bytes(document), "application/json", f"{stem}.json")
        table = table_of(version)
        if linked is not None:
            return self._calibration_export(run, version, linked, table, fmt, stem)
        output = run.estimator_config.get("output")
        unit = str(run.estimator_config.get("output_unit", ""))
        if fmt == "csv":
            from app.io.export import map_to_csv

            text = map_to_csv(table, value_name=str(output or "value"), value_unit=unit)
            return Download(text.encode(), "text/csv; charset=utf-8", f"{stem}.csv")
        from app.io.export import map_to_dcm

        name = _safe_name(str(output or run.estimator)).upper()
        description = _dcm_description(run, version)
        text = map_to_dcm(table, name=name, unit=unit, description=description)
        return Download(text.encode(), "text/plain; charset=utf-8", f"{stem}.dcm")

    def _calibration_export(
        self,
        run: Run,
        version: MapVersion,
        linked: cal.LinkedMap,
        table: Table,
        fmt: str,
        stem: str,
    ) -> Download:
        """DCM / CDFX keyed by the A2L name, or the patched memory image, of a linked run."""
        name = _safe_name(linked.char.name)
        if fmt == "dcm":
            description = _dcm_description(run, version)
            text = cal.dcm_text(linked.char, table, description=description)
            return Download(text.encode(), "text/plain; charset=utf-8", f"{stem}-{name}.dcm")
        if fmt == "cdfx":
            content = cal.cdfx_bytes(linked.char, table)
            return Download(content, "application/xml", f"{stem}-{name}.cdfx")
        image, image_format = cal.ecu_image(self.db, linked)
        patched = cal.patched_image(linked.a2l, linked.char, table, image)
        return Download(patched, "application/octet-stream", f"{stem}-{name}.{image_format}")

    def _map_document(self, run: Run, version: MapVersion) -> dict[str, Any]:
        """The ``mapwise adapt`` document of a version (the same function the CLI uses)."""
        table = table_of(version)
        snapshot = Snapshot(
            estimator=run.estimator,
            sample=version.summary.step,
            n_samples=run.n_samples,
            time_s=version.summary.time_s,
            state=None,
            chunk_start=0,
            table=table,
            variance=version.variances,
            rejected=version.rejected,
        )
        estimate_s = float(run.metrics.get("run_s") or 0.0)
        return map_document(snapshot, samples=version.summary.step, estimate_s=estimate_s)

    def _run_signals(self, run: Run) -> Signals:
        """The run's channels and per-sample outputs at full rate (outputs where all finite)."""
        with self.db.read() as s:
            datasets = DatasetRepo(s)
            dataset = datasets.get(run.dataset_id)
            stored = datasets.samples(run.dataset_id)
            segments = VersionRepo(s).segments(run.id)
        signals = load_signals(open_store(self.settings.store_url), stored, dataset.channels)
        used = [a["name"] for a in (run.table or {}).get("axes", [])] + list(run.signals.values())
        names = [n for n in dict.fromkeys(used) if n in signals] or signals.names
        outputs: dict[str, list[np.ndarray]] = {}
        for segment in segments:
            for name, values in segment.items():
                if name != "__status__":
                    outputs.setdefault(name, []).append(values)
        n = len(signals)
        full = {k: np.concatenate(v) for k, v in outputs.items()}
        full = {k: v for k, v in full.items() if v.size == n}
        start = 0
        for values in full.values():
            finite = np.isfinite(values)
            if finite.any():
                start = max(start, int(np.argmax(finite)))
        channels = {name: signals[name][start:] for name in names}
        units = {name: signals.units[name] for name in names}
        for name, values in full.items():
            if np.all(np.isfinite(values[start:])):
                # an estimate named like an input channel (the EKF's p_im_pa) keeps both
                key = name if name not in channels else f"{SeriesRole.OUTPUT}:{name}"
                channels[key] = values[start:]
                units[key] = ""
        return Signals(signals.time[start:], channels, units)

    def _mcap(self, run: Run) -> bytes:
        from app.io.export import MapVersionRecord, run_to_mcap

        with self.db.read() as s:
            records = VersionRepo(s).records(run.id)
        records = [r for r in records if r.values is not None]
        axes = [Axis.from_dict(a) for a in records[0].axes] if records and records[0].axes else None
        versions = [
            MapVersionRecord(
                step=r.summary.step,
                time_s=r.summary.time_s,
                values=np.asarray(r.values),
                variances=None if r.variances is None else np.asarray(r.variances),
                label=r.summary.label,
                final=r.summary.final,
            )
            for r in records
        ]
        metadata = {
            "run_id": str(run.id),
            "estimator": run.estimator,
            "dataset_id": str(run.dataset_id),
            "status": run.status,
        }
        return run_to_mcap(
            signals=self._run_signals(run), axes=axes, versions=versions, metadata=metadata
        )

    def _series_csv(self, run: Run) -> bytes:
        from app.io.export import series_to_csv

        signals = self._run_signals(run)
        channels = {n: (signals.units.get(n, ""), signals[n]) for n in signals.names}
        return series_to_csv(signals.time, channels).encode()


def _dcm_description(run: Run, version: MapVersion) -> str:
    """The DCM header line of an exported version: the run and the version's number 1…n in
    it (what the dashboard shows and links), the database id kept for traceability."""
    v = version.summary
    return f"mapwise run {run.id} ({run.estimator}), version {v.number} (id {v.id}, step {v.step})"


def _json_bytes(document: dict[str, Any]) -> bytes:
    import json

    return json.dumps(document).encode()
