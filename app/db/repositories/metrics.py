"""A run's final metrics and result series."""

from __future__ import annotations

from collections.abc import Mapping

from sqlalchemy import delete, select
from sqlalchemy.orm import Session, undefer

from app.db import blobs
from app.db.models import RunMetricRow
from app.domain import Series, SeriesRole


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
            arrays = {"time": item.time, "values": item.values}
            blob = blobs.pack_meta(arrays, {"role": None if item.role is None else str(item.role)})
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
            arrays, meta = blobs.unpack_meta(row.series)  # type: ignore[arg-type]
            role = None if meta.get("role") is None else SeriesRole(meta["role"])
            name = row.name.removeprefix("series:")
            out.append(Series(name, row.unit, arrays["time"], arrays["values"], role))
        return out
