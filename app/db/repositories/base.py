"""What every repository shares: id bounds and UTC timestamps."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime
from typing import Any, TypeVar

D = TypeVar("D")

MAX_ID = 2**31 - 1


def valid_id(id_: int) -> bool:
    """Ids beyond the databases' INTEGER cannot exist (and would overflow the driver)."""
    return 1 <= id_ <= MAX_ID


def aware(t: datetime | None) -> datetime | None:
    """SQLite returns naive datetimes; everything we store is UTC."""
    if t is None:
        return None
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def from_row(cls: type[D], row: object, **fields: Any) -> D:
    """The domain dataclass ``cls`` of an ORM row: each field not given in ``fields`` is the
    row's attribute of the same name, a datetime made UTC-aware (:func:`aware`).

    The dataclass counterpart of pydantic's ``model_validate(row, from_attributes=True)``:
    the domain objects stay frozen, slotted dataclasses (they hold numpy arrays and are
    built positionally), and nothing is validated again on its way out of the database.
    ``fields`` holds what is computed or copied (mutable JSON columns are copied so a caller
    cannot change the session's row through them).
    """
    values = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.name not in fields:
            value = getattr(row, f.name)
            values[f.name] = aware(value) if isinstance(value, datetime) else value
    return cls(**values, **fields)
