"""Base maps: stored tables a run can start from."""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session, undefer

from app.db import blobs
from app.db.models import BaseMapRow
from app.db.repositories.base import from_row
from app.domain import BaseMap, Page
from app.errors import NotFoundError


class BaseMapRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    @staticmethod
    def _map(row: BaseMapRow) -> BaseMap:
        values = blobs.unpack_array(row.values)
        assert values is not None
        return from_row(
            BaseMap, row, axes=list(row.axes), values=values, metrics=dict(row.metrics or {})
        )

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
