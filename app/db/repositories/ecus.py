"""ECUs: an A2L and the ECU's current values, stored as uploaded (docs/calibration.md)."""

from __future__ import annotations

from sqlalchemy import delete, func, select, update
from sqlalchemy.orm import Session

from app.db.models import EcuRow
from app.db.repositories.base import from_row, valid_id
from app.domain import Ecu, Page
from app.errors import NotFoundError


class EcuRepo:
    def __init__(self, session: Session) -> None:
        self.s = session

    def add(
        self,
        *,
        name: str,
        a2l_sha256: str,
        a2l: bytes,
        characteristics: int,
        values_format: str | None,
        values: bytes | None,
    ) -> Ecu:
        row = EcuRow(
            name=name,
            a2l_sha256=a2l_sha256,
            a2l=a2l,
            characteristics=characteristics,
            values_format=values_format,
            values=values,
        )
        self.s.add(row)
        self.s.flush()
        return from_row(Ecu, row)

    def _row(self, ecu_id: int) -> EcuRow:
        row = self.s.get(EcuRow, ecu_id) if valid_id(ecu_id) else None
        if row is None:
            raise NotFoundError(f"ECU {ecu_id} does not exist", field="ecu_id")
        return row

    def get(self, ecu_id: int) -> Ecu:
        return from_row(Ecu, self._row(ecu_id))

    def list(self, *, limit: int, offset: int) -> Page[Ecu]:
        total = self.s.scalar(select(func.count()).select_from(EcuRow)) or 0
        q = select(EcuRow).order_by(EcuRow.id.desc()).limit(limit).offset(offset)
        return Page([from_row(Ecu, r) for r in self.s.scalars(q)], total, limit, offset)

    def a2l(self, ecu_id: int) -> bytes:
        blob = self.s.scalar(select(EcuRow.a2l).where(EcuRow.id == ecu_id))
        if blob is None:
            raise NotFoundError(f"ECU {ecu_id} does not exist", field="ecu_id")
        return blob

    def values(self, ecu_id: int) -> bytes | None:
        self._row(ecu_id)
        return self.s.scalar(select(EcuRow.values).where(EcuRow.id == ecu_id))

    def set_values(self, ecu_id: int, *, values_format: str, values: bytes) -> Ecu:
        self._row(ecu_id)
        self.s.execute(
            update(EcuRow)
            .where(EcuRow.id == ecu_id)
            .values(values_format=values_format, values=values)
        )
        self.s.expire_all()
        return self.get(ecu_id)

    def delete(self, ecu_id: int) -> None:
        self._row(ecu_id)
        self.s.execute(delete(EcuRow).where(EcuRow.id == ecu_id))
