"""Datasets: ingest an upload, simulate a scenario, list, preview, delete.

The samples are stored in the database as one npz payload (time + channels, float64), so
any worker process or machine sharing the database can run on them. A simulated dataset
keeps its truth (true map, scoring points, true series) for the run metrics.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np

from app.db import blobs
from app.db.engine import Database
from app.db.repositories import DatasetRepo, RunRepo
from app.domain import Channel, Dataset, Page
from app.errors import ConflictError, InvalidRequestError
from app.io.ingest import IngestLimits, ingest
from app.services.decimate import finite_or_none, minmax_decimate
from estimation.errors import ConfigError
from estimation.scenarios import ScenarioData, get_scenario, scenarios
from estimation.signals import Signals
from estimation.table import Table

NAME_MAX = 200


def _clean_name(name: str | None, fallback: str) -> str:
    """A display name: never a path (only the last component of a client filename)."""
    text = (name or "").replace("\\", "/").rsplit("/", 1)[-1].strip()
    text = "".join(ch for ch in text if ch.isprintable())
    return (text or fallback)[:NAME_MAX]


def pack_signals(signals: Signals) -> bytes:
    arrays = {"time": signals.time}
    arrays |= {f"c{i}": signals[name] for i, name in enumerate(signals.names)}
    return blobs.pack(arrays)


def unpack_signals(blob: bytes, channels: list[Channel]) -> Signals:
    arrays = blobs.unpack(blob)
    return Signals(
        arrays["time"],
        {c.name: arrays[f"c{i}"] for i, c in enumerate(channels)},
        {c.name: c.unit for c in channels},
    )


@dataclass(frozen=True, slots=True)
class Truth:
    """What a simulated dataset knows that a log does not (see :class:`ScenarioData`)."""

    true_map: Table | None
    map_inputs: tuple[str, ...]
    map_output: str | None
    map_points: np.ndarray | None
    scored_series: dict[str, np.ndarray]

    def scenario_data(self, scenario: str, seed: int, signals: Signals) -> ScenarioData:
        return ScenarioData(
            scenario=scenario,
            seed=seed,
            signals=signals,
            truth={},
            true_map=self.true_map,
            map_inputs=self.map_inputs,
            map_output=self.map_output,
            map_points=self.map_points,
            scored_series=self.scored_series,
        )


def pack_truth(data: ScenarioData) -> bytes:
    names = list(data.scored_series)
    true_map = data.true_map
    meta: dict[str, Any] = {
        "true_map_axes": None if true_map is None else [a.to_dict() for a in true_map.axes],
        "map_inputs": list(data.map_inputs),
        "map_output": data.map_output,
        "scored": names,
    }
    arrays: dict[str, np.ndarray] = {f"s{i}": data.scored_series[n] for i, n in enumerate(names)}
    if data.true_map is not None:
        arrays["true_map"] = data.true_map.values
        arrays["map_points"] = data.scoring_points()
    return blobs.pack_meta(arrays, meta)


def unpack_truth(blob: bytes) -> Truth:
    arrays, meta = blobs.unpack_meta(blob)
    true_map = None
    if meta["true_map_axes"] is not None:
        true_map = Table.from_dict({"axes": meta["true_map_axes"], "values": arrays["true_map"]})
    return Truth(
        true_map=true_map,
        map_inputs=tuple(meta["map_inputs"]),
        map_output=meta["map_output"],
        map_points=arrays.get("map_points"),
        scored_series={n: arrays[f"s{i}"] for i, n in enumerate(meta["scored"])},
    )


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
    ) -> Dataset:
        """Parse and validate the whole file first; store it only if it is usable."""
        limits = IngestLimits(max_bytes=max_bytes, max_decompressed_bytes=max_decompressed_bytes)
        parsed = ingest(source, units=units, limits=limits)
        with self.db.write() as s:
            return DatasetRepo(s).add(
                name=_clean_name(name or filename, f"{parsed.source} upload"),
                source=parsed.source,
                rows=parsed.rows,
                rate_hz=parsed.rate_hz,
                duration_s=parsed.duration_s,
                time_column=parsed.time_column or "",
                channels=[Channel(c["name"], c["unit"]) for c in parsed.channels],
                payload=pack_signals(parsed.signals),
            )

    def simulate(
        self, scenario: str, *, seed: int, name: str | None, duration_s: float | None
    ) -> Dataset:
        if scenario not in scenarios():
            raise InvalidRequestError(
                f"unknown scenario {scenario!r}; choose one of {sorted(scenarios())}",
                field="scenario",
            )
        try:
            data = get_scenario(scenario).build(seed=seed, duration_s=duration_s)
        except ConfigError as exc:
            raise InvalidRequestError(str(exc), field="duration_s") from exc
        signals = data.signals
        rate = float(1.0 / np.median(np.diff(signals.time))) if len(signals) > 1 else 0.0
        with self.db.write() as s:
            return DatasetRepo(s).add(
                name=_clean_name(name, f"{scenario} (seed {seed})"),
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
                    if r.status in ("queued", "running")
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
