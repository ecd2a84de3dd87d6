"""Estimator states to and from the database, whatever the estimator.

Every state class offers ``to_dict``/``from_dict`` with a ``state_class`` tag; this module
picks the class from the tag. Arrays go to npz (:func:`app.db.blobs.pack_state`), so a
resumed run continues bit-for-bit from the persisted version.
"""

from __future__ import annotations

import importlib
from typing import Any

from app.db import blobs
from estimation.errors import StateError

# state_class tag → "module:Class"; filter states resolve their own subclasses.
_CLASSES = {
    "LpvState": "estimation.observers.lpv:LpvState",
    "TorqueState": "estimation.torque.estimators:TorqueState",
    "EkfState": "estimation.observers.ekf:EkfState",
}


def _state_class(tag: str) -> Any:
    if tag in _CLASSES:
        module, name = _CLASSES[tag].split(":")
        return getattr(importlib.import_module(module), name)
    from estimation.filters.state import STATE_CLASSES, FilterState

    if tag in STATE_CLASSES:
        return FilterState
    raise StateError(f"unknown estimator state class {tag!r}")


def dump_state(state: Any) -> bytes:
    return blobs.pack_state(state.to_dict())


def load_state(blob_or_data: bytes | dict[str, Any]) -> Any:
    data = blobs.unpack_state(blob_or_data) if isinstance(blob_or_data, bytes) else blob_or_data
    tag = str(data.get("state_class", ""))
    return _state_class(tag).from_dict(data)
