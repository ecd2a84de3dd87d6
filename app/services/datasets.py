"""Datasets: ingest an upload, simulate a scenario, list, preview, delete.

The samples are stored in the database as one npz payload (time + channels, float64), so
any worker process or machine sharing the database can run on them. A simulated dataset
keeps its truth (true map, scoring points, true series) for the run metrics.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any, BinaryIO

import numpy as np

from app.db.engine import Database
from app.db.repositories import DatasetRepo, RunRepo
from app.domain import Channel, Dataset, Page, RunStatus
from app.errors import ConflictError, InvalidRequestError
from app.io.decimate import finite_or_none, minmax_decimate
from app.io.ingest import IngestLimits, ingest
from app.io.names import check_name, without_refused
from app.io.payload import pack_signals, pack_truth, unpack_signals
from estimation.errors import EstimationError
from estimation.mismatch import MismatchLevel
from estimation.scenarios import get_scenario, scenarios
from estimation.signals import Signals

NAME_MAX = 200


def _dataset_name(name: str | None, filename: str | None, fallback: str) -> str:
    """The name as given (422 for a control or format character, :func:`check_name`); without
    one, the last component of the client's file name (its own directories say nothing)."""
    if name is not None and name.strip():
        return check_name(name, field="name")[:NAME_MAX]
    text = without_refused((filename or "").replace("\\", "/").rsplit("/", 1)[-1]).strip()
    return (text or fallback)[:NAME_MAX]


class DatasetService:
    def __init__(self, db: Database) -> None:
        self.db = db

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
    ) -> Dataset:
        """Parse and validate the whole file first; store it only if it is usable, with
        what ingest said about it: its notes and the masked samples per channel
        (`docs/data-formats.md#multi-rate`). ``channels``: the channels to keep (default
        all); ``raster``: ``100Hz``, ``10ms`` or ``channel:NAME`` (default the slowest kept
        channel's raster); ``rate_hz``: the rows' sample rate of a CSV without a time
        column, which is refused without it (a guessed time base is no time base)."""
        given = _dataset_name(name, filename, "")  # a bad name fails before the file is read
        limits = IngestLimits(max_bytes=max_bytes, max_decompressed_bytes=max_decompressed_bytes)
        parsed = ingest(
            source,
            units=units,
            limits=limits,
            channels=channels,
            raster=raster,
            rate_hz=rate_hz,
            time_required=True,
        )
        with self.db.write() as s:
            return DatasetRepo(s).add(
                name=given or f"{parsed.source} upload",
                source=parsed.source,
                rows=parsed.rows,
                rate_hz=parsed.rate_hz,
                duration_s=parsed.duration_s,
                time_column=parsed.time_column or "",
                channels=[
                    Channel(c["name"], c["unit"], parsed.masked.get(c["name"], 0))
                    for c in parsed.channels
                ],
                payload=pack_signals(parsed.signals),
                notes=parsed.notes,
            )

    def simulate(
        self,
        scenario: str,
        *,
        seed: int,
        name: str | None,
        duration_s: float | None,
        mismatch: MismatchLevel = "nominal",
    ) -> Dataset:
        if scenario not in scenarios():
            raise InvalidRequestError(
                f"unknown scenario {scenario!r}; choose one of {sorted(scenarios())}",
                field="scenario",
            )
        given = _dataset_name(name, None, f"{scenario} (seed {seed})")
        try:
            data = get_scenario(scenario).build(seed=seed, duration_s=duration_s, mismatch=mismatch)
        except EstimationError as exc:  # out of range, or too short for two samples
            raise InvalidRequestError(str(exc), field="duration_s") from exc
        signals = data.signals
        rate = float(1.0 / np.median(np.diff(signals.time))) if len(signals) > 1 else 0.0
        with self.db.write() as s:
            return DatasetRepo(s).add(
                name=given,
                source=f"scenario:{scenario}",
                rows=len(signals),
                rate_hz=rate,
                duration_s=float(signals.time[-1] - signals.time[0]),
                time_column="time",
                channels=[Channel(n, signals.units[n]) for n in signals.names],
                payload=pack_signals(signals),
                scenario=scenario,
                seed=seed,
                truth=pack_truth(data),
            )

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
            payload = repo.payload(dataset_id)
        return dataset, unpack_signals(payload, dataset.channels)

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
            repo.delete(dataset_id)

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
