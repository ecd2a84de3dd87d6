"""Run groups: sweeps and fleet batches."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.db.models import RunGroupRow
from app.db.repositories.base import from_row, valid_id
from app.domain import Page, RunGroup
from app.errors import NotFoundError


class GroupRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    @staticmethod
    def _group(row: RunGroupRow) -> RunGroup:
        return from_row(RunGroup, row, request=dict(row.request))

    def add(
        self,
        *,
        kind: str,
        name: str,
        estimator: str,
        request: dict[str, Any],
        metric: str | None = None,
        order: str | None = None,
    ) -> RunGroup:
        row = RunGroupRow(
            kind=kind, name=name, estimator=estimator, request=request, metric=metric, order=order
        )
        self.s.add(row)
        self.s.flush()
        return self._group(row)

    def get(self, group_id: int, kind: str) -> RunGroup:
        row = self.s.get(RunGroupRow, group_id) if valid_id(group_id) else None
        if row is None or row.kind != kind:
            raise NotFoundError(f"{kind} {group_id} does not exist", field=f"{kind}_id")
        return self._group(row)

    def list(self, kind: str, *, limit: int, offset: int) -> Page[RunGroup]:
        where = RunGroupRow.kind == kind
        total = self.s.scalar(select(func.count()).select_from(RunGroupRow).where(where)) or 0
        q = select(RunGroupRow).where(where).order_by(RunGroupRow.id.desc())
        rows = self.s.scalars(q.limit(limit).offset(offset))
        return Page([self._group(r) for r in rows], total, limit, offset)
