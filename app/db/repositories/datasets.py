"""Datasets: the logs, with their samples' object key and hash, and their truth blob."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session

from app.db.models import DatasetRow, MapVersionRow, RunMetricRow, RunRow
from app.db.repositories.base import from_row, valid_id
from app.domain import Channel, Dataset, Page, StoredSamples
from app.errors import NotFoundError


def _dataset(row: DatasetRow, has_truth: bool) -> Dataset:
    return from_row(
        Dataset,
        row,
        channels=[
            Channel(c["name"], c.get("unit", ""), c.get("masked", 0), _timing(c.get("timing")))
            for c in row.channels
        ],
        notes=tuple(row.notes or ()),
        has_truth=has_truth,
    )


def _timing(value: Any) -> tuple[float, float, float] | None:
    return None if value is None else (float(value[0]), float(value[1]), float(value[2]))


def _channel_json(channel: Channel) -> dict[str, Any]:
    """A channel as stored: its masked samples only when there are any, its timing only in
    a dataset stored as recorded."""
    stored: dict[str, Any] = {"name": channel.name, "unit": channel.unit}
    if channel.masked:
        stored["masked"] = channel.masked
    if channel.timing is not None:
        stored["timing"] = list(channel.timing)
    return stored


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
        scenario: str | None = None,
        seed: int | None = None,
        truth: bytes | None = None,
        notes: Sequence[str] = (),
    ) -> Dataset:
        row = DatasetRow(
            name=name,
            source=source,
            rows=rows,
            rate_hz=rate_hz,
            duration_s=duration_s,
            time_column=time_column,
            channels=[_channel_json(c) for c in channels],
            notes=list(notes) or None,
            scenario=scenario,
            seed=seed,
            truth=truth,
        )
        self.s.add(row)
        self.s.flush()
        return _dataset(row, truth is not None)

    def _row(self, dataset_id: int) -> DatasetRow:
        row = self.s.get(DatasetRow, dataset_id) if valid_id(dataset_id) else None
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

    def attach_samples(self, dataset_id: int, key: str, sha256: str) -> None:
        """Record the object holding the dataset's samples (stored before the commit)."""
        row = self._row(dataset_id)
        row.artifact, row.content_sha256 = key, sha256
        self.s.flush()

    def samples_key(self, dataset_id: int) -> str | None:
        return self.s.scalar(select(DatasetRow.artifact).where(DatasetRow.id == dataset_id))

    def samples(self, dataset_id: int) -> StoredSamples:
        """The key and hash of the dataset's samples (404 for an unknown dataset)."""
        q = select(DatasetRow.artifact, DatasetRow.content_sha256).where(
            DatasetRow.id == dataset_id
        )
        found = self.s.execute(q).first() if valid_id(dataset_id) else None
        if found is None:
            raise NotFoundError(f"dataset {dataset_id} does not exist", field="dataset_id")
        key, sha256 = found
        if key is None or sha256 is None:  # only inside the transaction that adds it
            raise NotFoundError(f"dataset {dataset_id} has no samples yet", field="dataset_id")
        return StoredSamples(dataset_id, key, sha256)

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
