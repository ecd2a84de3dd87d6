"""Datasets: ingest an upload, simulate a scenario, list, preview, delete.

The samples are one Parquet object in the artifact store (:mod:`app.store`, time + channels,
float64; an upload whose channels are on different timestamps and came without a raster is
stored as recorded, and each read puts the channels it needs on the slowest raster among
them, `docs/data-formats.md#multi-rate`), its key and SHA-256 in the dataset's row, so any
worker process or machine sharing the database and the store can run on them. The object is
written before the row commits (removed again if the commit fails) and deleted after the
row's delete commits. A simulated dataset keeps its truth (true map, scoring points, true
series) in the row, for the run metrics.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any, BinaryIO

import numpy as np

from app.db.engine import Database
from app.db.repositories import DatasetRepo, RunRepo
from app.domain import Channel, Dataset, Page, RunStatus
from app.errors import ConflictError, InvalidRequestError
from app.io.csv_stream import STREAM_MIN_BYTES, NotDense, StreamedCsv, stream_csv
from app.io.decimate import finite_or_none, minmax_decimate
from app.io.errors import too_large
from app.io.ingest import IngestLimits, ParsedLog, detect_format, ingest
from app.io.names import check_name, without_refused
from app.io.payload import pack_truth
from app.io.resample import span_of
from app.services.admission import human_bytes
from app.services.dataset_child import DatasetChild, SimulationRequest, WholeUpload
from app.store import (
    ArtifactStore,
    StagedDataset,
    delete_dataset,
    load_signals,
    open_store,
    save_staged,
    stage_recorded,
    stage_signals,
    staging_file,
)
from app.store.parquet_signals import SignalsWriter
from estimation.errors import EstimationError
from estimation.mismatch import MismatchLevel
from estimation.progress import Progress, reporting
from estimation.scenarios import get_scenario, scenarios
from estimation.signals import Signals

NAME_MAX = 200
log = logging.getLogger("mapwise.datasets")


HERE_MAX_BYTES = 1 << 20
"""A CSV smaller than this is read whole in the server even with a dataset child: pyarrow's
reader is loaded there anyway, the parse holds a few MiB, and a hop to the child would cost
more than it."""
WHOLE_READ_FACTOR = {"csv": 6.0, "mdf4": 5.0, "mcap": 20.0}
"""Peak memory of a whole read per byte of the file, by format (measured 4.6 for a sparse
CSV, 3.8 for an MDF4 log and 14.7–16.4 for an MCAP log of JSON messages,
scripts/whole_read.py, docs/data-formats.md#whole-reads): an upload predicted over the
memory budget is refused before it is read."""


def _sized(source: BinaryIO | bytes | os.PathLike[str]) -> tuple[int, str]:
    """The upload's size in bytes and its format (:func:`detect_format`; the file rewound)."""
    with _opened(source) as file:
        size = file.seek(0, io.SEEK_END)
        file.seek(0)
        head = file.read(4096)
        file.seek(0)
    return size, detect_format(head)


def check_whole_read(size: int, kind: str, memory_mb: float | None) -> None:
    """413 naming ``file`` when reading a ``kind`` file of ``size`` bytes whole is predicted
    (:data:`WHOLE_READ_FACTOR`) to need more than ``memory_mb`` (``None``: no budget)."""
    if memory_mb is None:
        return
    predicted = WHOLE_READ_FACTOR[kind] * size
    if predicted > memory_mb * 2**20:
        raise too_large(
            f"reading this {kind.upper()} file of {human_bytes(size)} whole needs about "
            f"{human_bytes(predicted)} (predicted) > {memory_mb:g} MiB budget "
            "(MAPWISE_RUN_MEMORY_MB); upload a dense CSV, which streams, or fewer channels"
        )


def _dataset_name(name: str | None, filename: str | None, fallback: str) -> str:
    """The name as given (422 for a control or format character, :func:`check_name`); without
    one, the last component of the client's file name (its own directories say nothing)."""
    if name is not None and name.strip():
        return check_name(name, field="name")[:NAME_MAX]
    text = without_refused((filename or "").replace("\\", "/").rsplit("/", 1)[-1]).strip()
    return (text or fallback)[:NAME_MAX]


def _timing(parsed: ParsedLog) -> dict[str, tuple[float, float, float]]:
    """Per channel stored as recorded: its first and last valid time and its median time
    step (:func:`app.io.resample.span_of`, the resample rule's), so a run's rows and rate
    are known before its samples are read (:meth:`Dataset.rows_for`) and a streamed run
    can plan its raster without a pass over them (:mod:`app.store.raster_rows`)."""
    spans = (span_of(track) for track in parsed.recorded)
    return {s.name: (s.start, s.stop, s.step) for s in spans}


def _add_streamed(repo: DatasetRepo, name: str, streamed: StreamedCsv) -> Dataset:
    return repo.add(
        name=name or "csv upload",
        source="csv",
        rows=streamed.rows,
        rate_hz=streamed.rate_hz,
        duration_s=streamed.duration_s,
        time_column=streamed.time_column or "",
        channels=[Channel(n, u) for n, u in streamed.channels],
        notes=streamed.notes,
    )


@contextlib.contextmanager
def _opened(source: BinaryIO | bytes | os.PathLike[str]) -> Iterator[BinaryIO]:
    """The upload as a file object at its start (a path opened, bytes wrapped)."""
    if isinstance(source, os.PathLike):
        with open(source, "rb") as f:
            yield f
    elif isinstance(source, bytes | bytearray | memoryview):
        yield io.BytesIO(source)
    else:
        yield source


class DatasetService:
    def __init__(
        self,
        db: Database,
        store: ArtifactStore | None = None,
        *,
        in_child: bool = False,
        memory_mb: float | None = None,
    ) -> None:
        self.db = db
        self.store = store or open_store()
        self.child: DatasetChild | None = None
        if in_child and db.shared and self.store.shared:
            self.child = DatasetChild(db.url, self.store.url, memory_mb)

    def close(self) -> None:
        """End the dataset child, if one was started."""
        if self.child is not None:
            self.child.close()

    def _store(
        self, signals: Signals | ParsedLog, add: Callable[[DatasetRepo], Dataset]
    ) -> Dataset:
        """Stage the samples as Parquet and store them (:meth:`_store_staged`)."""
        with self._staged(signals) as staged:
            return self._store_staged(staged, add)

    def _store_staged(
        self, staged: StagedDataset, add: Callable[[DatasetRepo], Dataset]
    ) -> Dataset:
        """Add the row, put the staged object under the row's id and commit; an object whose
        row did not commit is removed again."""
        stored: tuple[int, str] | None = None
        try:
            with self.db.write() as s:
                repo = DatasetRepo(s)
                dataset = add(repo)
                stored = (dataset.id, save_staged(self.store, dataset.id, staged))
                repo.attach_samples(dataset.id, stored[1], staged.sha256)
            return dataset
        except BaseException:
            if stored is not None:
                delete_dataset(self.store, *stored)
            raise

    @contextlib.contextmanager
    def _staged(self, samples: Signals | ParsedLog) -> Iterator[StagedDataset]:
        """Signals as they are; a parsed upload as recorded when ingest kept its channels on
        their own timestamps (:attr:`ParsedLog.recorded`), else its signals."""
        if isinstance(samples, Signals):
            with stage_signals(self.store, samples) as staged:
                yield staged
        elif samples.recorded:
            units = dict(samples.signals.units)
            with stage_recorded(self.store, samples.recorded, units) as staged:
                yield staged
        else:
            with stage_signals(self.store, samples.signals) as staged:
                yield staged

    def upload(
        self,
        source: BinaryIO | bytes | os.PathLike[str],
        *,
        filename: str | None,
        name: str | None,
        units: dict[str, str] | None,
        max_bytes: int,
        max_decompressed_bytes: int = IngestLimits.max_decompressed_bytes,
        channels: Sequence[str] | None = None,
        raster: str | None = None,
        rate_hz: float | None = None,
        max_whole_bytes: int | None = None,
        stream_min_bytes: int = STREAM_MIN_BYTES,
    ) -> Dataset:
        """Parse and validate the whole file first; store it only if it is usable, with
        what ingest said about it: its notes and the masked samples per channel
        (`docs/data-formats.md#multi-rate`). ``channels``: the channels to keep (default
        all); ``raster``: ``100Hz``, ``10ms`` or ``channel:NAME``, the samples resampled
        onto it now; without one, channels on different timestamps are stored as recorded
        and each read resamples the channels it needs onto the slowest raster among them
        (the row's ``rows``, ``rate_hz`` and ``duration_s`` describe the whole-log read, on
        the slowest kept channel's raster); ``rate_hz``: the rows' sample rate of a CSV
        without a time column, which is refused without it (a guessed time base is no time
        base).

        A dense CSV of at least ``stream_min_bytes`` without a raster streams into the store
        (:mod:`app.io.csv_stream`): the process never holds the whole log. Anything else is
        read whole (:meth:`upload_whole`), and refused (413) over ``max_whole_bytes``
        (default ``max_bytes``); with ``in_child`` (the server's setting), by the dataset
        child (:mod:`app.services.dataset_child`) under the ``memory_mb`` budget, but for a
        CSV under :data:`HERE_MAX_BYTES`; refused (413) before it is read when predicted over
        that budget (:func:`check_whole_read`)."""
        given = _dataset_name(name, filename, "")  # a bad name fails before the file is read
        whole = max_bytes if max_whole_bytes is None else min(max_whole_bytes, max_bytes)
        if raster is None:
            streamed = self._upload_streamed(
                source,
                given,
                units=units,
                channels=channels,
                rate_hz=rate_hz,
                max_bytes=max_bytes,
                max_whole_bytes=whole,
                min_bytes=stream_min_bytes,
            )
            if streamed is not None:
                return streamed
        upload = WholeUpload(
            name=given,
            units=units,
            channels=None if channels is None else list(channels),
            raster=raster,
            rate_hz=rate_hz,
            max_bytes=whole,
            max_decompressed_bytes=max_decompressed_bytes,
        )
        if self.child is None:
            return self.upload_whole(source, upload)
        size, kind = _sized(source)
        if kind == "csv" and size < HERE_MAX_BYTES:
            return self.upload_whole(source, upload)
        check_whole_read(size, kind, self.child.memory_mb)
        return self.get(self.child.upload(source, upload))

    def upload_whole(
        self, source: BinaryIO | bytes | os.PathLike[str], upload: WholeUpload
    ) -> Dataset:
        """:meth:`upload` of a file read whole, in this process: parsed and validated whole
        (:func:`~app.io.ingest.ingest`), then stored."""
        limits = IngestLimits(
            max_bytes=upload.max_bytes, max_decompressed_bytes=upload.max_decompressed_bytes
        )
        parsed = ingest(
            source,
            units=upload.units,
            limits=limits,
            channels=upload.channels,
            raster=upload.raster,
            rate_hz=upload.rate_hz,
            time_required=True,
        )
        timing = _timing(parsed)
        return self._store(
            parsed,
            lambda repo: repo.add(
                name=upload.name or f"{parsed.source} upload",
                source=parsed.source,
                rows=parsed.rows,
                rate_hz=parsed.rate_hz,
                duration_s=parsed.duration_s,
                time_column=parsed.time_column or "",
                channels=[
                    Channel(
                        c["name"],
                        c["unit"],
                        parsed.masked.get(c["name"], 0),
                        timing.get(c["name"]),
                    )
                    for c in parsed.channels
                ],
                notes=parsed.notes,
            ),
        )

    def _upload_streamed(
        self,
        source: BinaryIO | bytes | os.PathLike[str],
        given: str,
        *,
        units: dict[str, str] | None,
        channels: Sequence[str] | None,
        rate_hz: float | None,
        max_bytes: int,
        max_whole_bytes: int,
        min_bytes: int,
    ) -> Dataset | None:
        """The dataset of a dense CSV streamed into the store; ``None`` (the file rewound)
        when the upload is to be read whole. 413 for a file over ``max_bytes``, or over
        ``max_whole_bytes`` that cannot stream (saying why)."""
        with _opened(source) as file:
            size = file.seek(0, io.SEEK_END)
            file.seek(0)
            if size > max_bytes:
                raise too_large(f"file is {size} bytes, the limit is {max_bytes} bytes")
            if size < min_bytes:
                return None
            head = file.read(4096)
            file.seek(0)
            kind = detect_format(head)
            if kind != "csv":
                if size > max_whole_bytes:
                    raise too_large(
                        f"file is {size} bytes; an {kind.upper()} log is read whole, which is "
                        f"limited to {max_whole_bytes} bytes (MAPWISE_MAX_WHOLE_MB); only a "
                        "dense CSV streams"
                    )
                return None
            limits = IngestLimits()
            with staging_file(self.store) as path:
                try:
                    streamed = stream_csv(
                        file,
                        lambda channels: SignalsWriter(path, channels),
                        units=units,
                        time_column=None,
                        channels=channels,
                        rate_hz=rate_hz,
                        max_header_bytes=limits.max_header_bytes,
                        max_channels=limits.max_channels,
                        min_samples=limits.min_samples,
                    )
                except NotDense as why:
                    file.seek(0)
                    if size > max_whole_bytes:
                        raise too_large(
                            f"file is {size} bytes and cannot stream ({why}): a CSV is "
                            f"read whole then, which is limited to {max_whole_bytes} bytes "
                            "(MAPWISE_MAX_WHOLE_MB)"
                        ) from None
                    log.info("upload read whole: %s", why)
                    return None
                staged = StagedDataset(path, streamed.sha256)
                return self._store_staged(staged, lambda repo: _add_streamed(repo, given, streamed))

    def simulate(
        self,
        scenario: str,
        *,
        seed: int,
        name: str | None,
        duration_s: float | None,
        mismatch: MismatchLevel = "nominal",
        progress: Progress | None = None,
    ) -> Dataset:
        """Simulate ``scenario`` and store it with its truth. ``progress``, when given, is
        what the build reports its integrator's steps into (:mod:`estimation.progress`).

        With ``in_child`` (the server's setting) the dataset child simulates and stores it
        under the ``memory_mb`` budget (:mod:`app.services.dataset_child`), unless the
        database or the store lives in this process's memory, where no child could reach it.
        """
        self.check_simulation(scenario, duration_s, name)
        request = SimulationRequest(scenario, seed, name, duration_s, mismatch)
        if self.child is None:
            return self.simulate_here(request, progress)
        return self.get(self.child.simulate(request, progress))

    def simulate_here(self, request: SimulationRequest, progress: Progress | None) -> Dataset:
        """:meth:`simulate` in this process."""
        scenario = request.scenario
        given = _dataset_name(request.name, None, f"{scenario} (seed {request.seed})")
        try:
            with reporting(progress or Progress()):
                data = get_scenario(scenario).build(
                    seed=request.seed, duration_s=request.duration_s, mismatch=request.mismatch
                )
        except EstimationError as exc:  # out of range, or too short for two samples
            raise InvalidRequestError(str(exc), field="duration_s") from exc
        signals = data.signals
        rate = float(1.0 / np.median(np.diff(signals.time))) if len(signals) > 1 else 0.0
        truth = pack_truth(data)
        return self._store(
            signals,
            lambda repo: repo.add(
                name=given,
                source=f"scenario:{scenario}",
                rows=len(signals),
                rate_hz=rate,
                duration_s=float(signals.time[-1] - signals.time[0]),
                time_column="time",
                channels=[Channel(n, signals.units[n]) for n in signals.names],
                scenario=scenario,
                seed=request.seed,
                truth=truth,
            ),
        )

    @staticmethod
    def check_simulation(scenario: str, duration_s: float | None, name: str | None) -> None:
        """The 422 a simulation of ``scenario`` for ``duration_s`` named ``name`` would end in,
        raised before anything runs: an unknown scenario, a duration outside its record, a
        name with a control or format character."""
        _dataset_name(name, None, "")
        if scenario not in scenarios():
            raise InvalidRequestError(
                f"unknown scenario {scenario!r}; choose one of {sorted(scenarios())}",
                field="scenario",
            )
        try:
            get_scenario(scenario).check_duration(duration_s)
        except EstimationError as exc:
            raise InvalidRequestError(str(exc), field="duration_s") from exc

    def get(self, dataset_id: int) -> Dataset:
        with self.db.read() as s:
            return DatasetRepo(s).get(dataset_id)

    def list(self, *, limit: int, offset: int) -> Page[Dataset]:
        with self.db.read() as s:
            return DatasetRepo(s).list(limit=limit, offset=offset)

    def signals(self, dataset_id: int) -> tuple[Dataset, Signals]:
        with self.db.read() as s:
            repo = DatasetRepo(s)
            dataset = repo.get(dataset_id)
            stored = repo.samples(dataset_id)
        signals = load_signals(self.store, stored, dataset.channels)
        return dataset, signals

    def delete(self, dataset_id: int, *, force: bool) -> None:
        with self.db.write() as s:
            repo = DatasetRepo(s)
            repo.get(dataset_id)
            n_runs = repo.run_count(dataset_id)
            if n_runs and not force:
                raise ConflictError(
                    f"dataset {dataset_id} is used by {n_runs} run(s); delete with ?force=true "
                    "to remove them too",
                    field="dataset_id",
                )
            if force:
                active = [
                    r.id
                    for r in RunRepo(s).list(limit=1_000_000, offset=0, dataset_id=dataset_id).items
                    if r.status in (RunStatus.QUEUED, RunStatus.RUNNING)
                ]
                if active:
                    raise ConflictError(
                        f"runs {active} on dataset {dataset_id} are still active; "
                        "cancel them first",
                        field="dataset_id",
                    )
            key = repo.samples_key(dataset_id)
            repo.delete(dataset_id)
        if key is not None:
            delete_dataset(self.store, dataset_id, key)

    def preview(self, dataset_id: int, *, points: int) -> dict[str, Any]:
        dataset, signals = self.signals(dataset_id)
        time, channels = minmax_decimate(signals.time, signals.channels, points)
        return {
            "time": finite_or_none(time),
            "channels": {
                c.name: {"unit": c.unit, "values": finite_or_none(channels[c.name])}
                for c in dataset.channels
            },
        }
