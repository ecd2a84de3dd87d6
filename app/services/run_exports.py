"""A run's exports: the map as JSON, CSV, DCM, CDFX or a patched ECU image, and the run as
MCAP or a series CSV (``GET /api/runs/{id}/export``, docs/rest-api.md)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.config import Settings
from app.db.engine import Database
from app.db.repositories import DatasetRepo, RunRepo, VersionRepo
from app.domain import MapVersion, Run, SeriesRole
from app.errors import ConflictError, InvalidRequestError
from app.io.errors import InputError
from app.io.map_json import map_document
from app.runs.options import run_raster
from app.services import calibration_runs as cal
from app.services.truth_map import map_quantity
from app.store import load_signals, open_store
from estimation.estimator import Snapshot
from estimation.signals import Signals
from estimation.table import Axis, Table

EXPORT_FORMATS = ("json", "csv", "mcap", "dcm", "cdfx", "image")


@dataclass(frozen=True, slots=True)
class Download:
    content: bytes
    media_type: str
    filename: str


def table_of(version: MapVersion) -> Table:
    if version.axes is None or version.values is None:
        raise ConflictError("this run has no map", field="format")
    return Table([Axis.from_dict(a) for a in version.axes], version.values)


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "map"


class RunExports:
    """Builds a run's export files from the database and the artifact store."""

    def __init__(self, db: Database, settings: Settings) -> None:
        self.db = db
        self.settings = settings

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
        quantity, unit = map_quantity(run)
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
        if fmt == "csv":
            from app.io.export import map_to_csv

            text = map_to_csv(table, value_name=quantity or "value", value_unit=unit)
            return Download(text.encode(), "text/csv; charset=utf-8", f"{stem}.csv")
        from app.io.export import map_to_dcm

        name = _safe_name(quantity or run.estimator).upper()
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
        quantity, unit = map_quantity(run)
        return map_document(
            snapshot,
            samples=version.summary.step,
            estimate_s=estimate_s,
            quantity=quantity,
            unit=unit,
        )

    def _run_signals(self, run: Run) -> Signals:
        """The run's channels and per-sample outputs at full rate (outputs where all finite).

        The samples are read as the run's worker read them: the same channels, so a dataset
        stored as recorded comes back on the raster the run used
        (`docs/data-formats.md#multi-rate`)."""
        with self.db.read() as s:
            datasets = DatasetRepo(s)
            dataset = datasets.get(run.dataset_id)
            stored = datasets.samples(run.dataset_id)
            truth = datasets.truth(run.dataset_id)
            segments = VersionRepo(s).segments(run.id)
        used = [a["name"] for a in (run.table or {}).get("axes", [])] + list(run.signals.values())
        names = [n for n in dict.fromkeys(used) if n in {c.name for c in dataset.channels}]
        store = open_store(self.settings.store_url)
        raster = run_raster(run.config)
        read = _read_by_run(run, truth) + names
        if raster is not None and raster.channel is not None:
            read.append(raster.channel)
        read = list(dict.fromkeys(read))
        signals = load_signals(store, stored, dataset.channels, read or None, raster=raster)
        names = names or signals.names
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
        output_units = _output_units(run)
        for name, values in full.items():
            if np.all(np.isfinite(values[start:])):
                # an estimate named like an input channel (the EKF's p_im_pa) keeps both
                key = name if name not in channels else f"{SeriesRole.OUTPUT}:{name}"
                channels[key] = values[start:]
                units[key] = output_units.get(name, "")
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


def _read_by_run(run: Run, truth: bytes | None) -> list[str]:
    """The channels the run's worker read (:func:`app.runs.results.channels_read` and the
    gates'), ``[]`` when its estimator no longer builds from its config (then every channel
    is read)."""
    from app.io.payload import unpack_truth
    from app.runs.gates import gate_channels
    from app.runs.results import channels_read
    from estimation.errors import EstimationError
    from estimation.registry import get_spec

    try:
        estimator = get_spec(run.estimator).build(run.estimator_config)
    except (EstimationError, ValueError, KeyError):
        return []
    unpacked = None if truth is None else unpack_truth(truth)
    return channels_read(run, estimator, unpacked) + gate_channels(run.config)


def _dcm_description(run: Run, version: MapVersion) -> str:
    """The DCM header line of an exported version: the run and the version's number 1…n in
    it (what the dashboard shows and links), the database id kept for traceability."""
    v = version.summary
    return f"mapwise run {run.id} ({run.estimator}), version {v.number} (id {v.id}, step {v.step})"


def _json_bytes(document: dict[str, Any]) -> bytes:
    import json

    return json.dumps(document).encode()


def _output_units(run: Run) -> dict[str, str]:
    """The unit of each per-sample estimator output of a run: the registry's
    ``output_units`` (docs/adding-an-estimator.md), where ``""`` means the unit of the run's
    output channel, as the stored series (``app.runs.results``) have it."""
    from estimation.registry import get_spec

    out_unit = str(run.estimator_config.get("output_unit") or "")
    spec = get_spec(run.estimator)
    return {name: unit or out_unit for name, unit in spec.output_units.items()}
