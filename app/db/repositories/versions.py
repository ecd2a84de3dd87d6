"""Map versions: each persisted snapshot of a run, with its arrays, state and output
segment."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session, undefer

from app.db import blobs
from app.db.models import MapVersionRow
from app.db.repositories.base import from_row
from app.domain import MapVersion, Page, ResumePoint, VersionSummary
from app.errors import NotFoundError


def _summary(row: MapVersionRow, number: int) -> VersionSummary:
    return from_row(VersionSummary, row, number=number)


def _unpack_dict(blob: bytes | None) -> dict[str, np.ndarray]:
    return {} if blob is None else blobs.unpack(blob)


class VersionRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def add(
        self,
        *,
        run_id: int,
        step: int,
        time_s: float,
        final: bool,
        axes: list[dict[str, Any]] | None,
        values: np.ndarray | None,
        variances: np.ndarray | None,
        visits: np.ndarray | None,
        cell_rejections: Mapping[str, np.ndarray],
        state: bytes | None,
        segment: Mapping[str, np.ndarray] | None,
        rejected: Mapping[str, int],
        label: str | None = None,
    ) -> VersionSummary:
        row = MapVersionRow(
            run_id=run_id,
            step=step,
            time_s=time_s,
            final=final,
            label=label,
            axes=axes,
            values=None if values is None else blobs.pack_array(values),
            variances=None if variances is None else blobs.pack_array(variances),
            visits=None if visits is None else blobs.pack_array(visits),
            cell_rejections=blobs.pack(cell_rejections) if cell_rejections else None,
            state=state,
            segment=None if segment is None else blobs.pack(segment),
            rejected={k: int(v) for k, v in rejected.items()},
        )
        self.s.add(row)
        self.s.flush()
        return _summary(row, self._number(row))

    def _number(self, row: MapVersionRow) -> int:
        """The row's place 1…n in its run: the versions at or before its step (steps are
        unique per run, ``uq_map_versions_run_step``)."""
        q = (
            select(func.count())
            .select_from(MapVersionRow)
            .where(MapVersionRow.run_id == row.run_id, MapVersionRow.step <= row.step)
        )
        return int(self.s.scalar(q) or 0)

    def list(self, run_id: int, *, limit: int, offset: int) -> Page[VersionSummary]:
        where = MapVersionRow.run_id == run_id
        total = self.s.scalar(select(func.count()).select_from(MapVersionRow).where(where)) or 0
        q = (
            select(MapVersionRow)
            .where(where)
            .order_by(MapVersionRow.step, MapVersionRow.id)
            .limit(limit)
            .offset(offset)
        )
        rows = self.s.scalars(q)
        return Page([_summary(r, offset + k + 1) for k, r in enumerate(rows)], total, limit, offset)

    def _full(
        self, where: Any, order: Any = None, *, offset: int = 0, number: int | None = None
    ) -> MapVersion | None:
        """The first row matching ``where`` (in ``order``, after ``offset``) with its arrays;
        ``number``: its place in the run when the caller knows it (else counted)."""
        q = (
            select(MapVersionRow)
            .options(
                undefer(MapVersionRow.values),
                undefer(MapVersionRow.variances),
                undefer(MapVersionRow.visits),
                undefer(MapVersionRow.cell_rejections),
            )
            .where(*where)
        )
        if order is not None:
            q = q.order_by(order).offset(offset).limit(1)
        row = self.s.scalars(q).first()
        if row is None:
            return None
        return MapVersion(
            summary=_summary(row, self._number(row) if number is None else number),
            axes=row.axes,
            values=blobs.unpack_array(row.values),
            variances=blobs.unpack_array(row.variances),
            visits=blobs.unpack_array(row.visits),
            cell_rejections=_unpack_dict(row.cell_rejections),
            rejected={k: int(v) for k, v in (row.rejected or {}).items()},
        )

    def get(self, run_id: int, version_id: int) -> MapVersion:
        found = self._full([MapVersionRow.run_id == run_id, MapVersionRow.id == version_id])
        if found is None:
            raise NotFoundError(
                f"run {run_id} has no version with id {version_id}", field="version_id"
            )
        return found

    def by_number(self, run_id: int, number: int) -> MapVersion:
        """Version ``number`` (1…n by step) of the run; 404 naming the number and how many
        the run has."""
        found = (
            self._full(
                [MapVersionRow.run_id == run_id],
                order=MapVersionRow.step,
                offset=number - 1,
                number=number,
            )
            if number >= 1
            else None
        )
        if found is None:
            raise NotFoundError(
                f"run {run_id} has no version {number} ({self._count_text(run_id)})",
                field="number",
            )
        return found

    def count(self, run_id: int) -> int:
        where = MapVersionRow.run_id == run_id
        return int(self.s.scalar(select(func.count()).select_from(MapVersionRow).where(where)) or 0)

    def _count_text(self, run_id: int) -> str:
        n = self.count(run_id)
        return "it has none yet" if n == 0 else f"it has 1…{n}" if n > 1 else "it has 1"

    def latest(self, run_id: int) -> MapVersion | None:
        """The final version, else the last one persisted."""
        return self._full(
            [MapVersionRow.run_id == run_id],
            order=(MapVersionRow.step.desc()),
        )

    def set_label(self, run_id: int, version_id: int, label: str | None) -> VersionSummary:
        row = self.s.get(MapVersionRow, version_id)
        if row is None or row.run_id != run_id:
            raise NotFoundError(
                f"run {run_id} has no version with id {version_id}", field="version_id"
            )
        row.label = label
        self.s.flush()
        return _summary(row, self._number(row))

    def resume_point(self, run_id: int) -> ResumePoint | None:
        """The last version with a state, plus every earlier version's output segment."""
        q = (
            select(MapVersionRow)
            .options(
                undefer(MapVersionRow.state),
                undefer(MapVersionRow.visits),
                undefer(MapVersionRow.cell_rejections),
            )
            .where(MapVersionRow.run_id == run_id, MapVersionRow.state.is_not(None))
            .order_by(MapVersionRow.step.desc())
            .limit(1)
        )
        row = self.s.scalars(q).first()
        if row is None or row.state is None:
            return None
        segments_q = (
            select(MapVersionRow.segment)
            .where(MapVersionRow.run_id == run_id, MapVersionRow.step <= row.step)
            .order_by(MapVersionRow.step)
        )
        segments = [blobs.unpack(b) for b in self.s.scalars(segments_q) if b is not None]
        return ResumePoint(
            version_id=row.id,
            step=row.step,
            state=blobs.unpack_state(row.state),
            visits=blobs.unpack_array(row.visits),
            cell_rejections=_unpack_dict(row.cell_rejections),
            segments=segments,
        )

    def segments(self, run_id: int) -> list[dict[str, np.ndarray]]:
        """Every version's output segment, in order (together: the run's per-sample outputs)."""
        q = (
            select(MapVersionRow.segment)
            .where(MapVersionRow.run_id == run_id)
            .order_by(MapVersionRow.step)
        )
        return [blobs.unpack(b) for b in self.s.scalars(q) if b is not None]

    def records(self, run_id: int) -> list[MapVersion]:
        """Every version with its arrays, in order."""
        q = select(MapVersionRow.id).where(MapVersionRow.run_id == run_id)
        ids = list(self.s.scalars(q.order_by(MapVersionRow.step)))
        where = [MapVersionRow.run_id == run_id]
        found = [
            self._full([*where, MapVersionRow.id == i], number=k + 1) for k, i in enumerate(ids)
        ]
        return [v for v in found if v is not None]

    def has_step(self, run_id: int, step: int) -> bool:
        q = select(MapVersionRow.id).where(
            MapVersionRow.run_id == run_id, MapVersionRow.step == step
        )
        return self.s.scalar(q.limit(1)) is not None

    def delete_after(self, run_id: int, step: int) -> None:
        self.s.execute(
            delete(MapVersionRow).where(MapVersionRow.run_id == run_id, MapVersionRow.step > step)
        )
