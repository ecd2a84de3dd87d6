"""Base maps: stored tables a run can start from."""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session, undefer

from app.db import blobs
from app.db.models import BaseMapRow, MapVersionRow
from app.db.repositories.base import from_row
from app.domain import BaseMap, Page
from app.errors import NotFoundError


class BaseMapRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def _map(self, row: BaseMapRow) -> BaseMap:
        values = blobs.unpack_array(row.values)
        assert values is not None
        return from_row(
            BaseMap,
            row,
            axes=list(row.axes),
            values=values,
            metrics=dict(row.metrics or {}),
            version_number=self._version_number(row),
        )

    def _version_number(self, row: BaseMapRow) -> int | None:
        """The promoted version's number in its run (its rank by step, as
        :meth:`VersionRepo._number`); ``None`` once the version is gone (the lineage keeps
        the ids, the number needs the run's versions)."""
        if row.run_id is None or row.version_id is None:
            return None
        step = (
            select(MapVersionRow.step)
            .where(MapVersionRow.id == row.version_id, MapVersionRow.run_id == row.run_id)
            .scalar_subquery()
        )
        q = (
            select(func.count())
            .select_from(MapVersionRow)
            .where(MapVersionRow.run_id == row.run_id, MapVersionRow.step <= step)
        )
        return int(self.s.scalar(q) or 0) or None

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
