"""Arrays as compact binary blobs (``.npz``), never as text per cell.

``pack`` stores named arrays (float64 stays float64 so resumed runs and exports are exact);
``unpack`` refuses pickled objects, so a blob from the database can never execute code.
Estimator states (``to_dict`` output: scalars plus ``{"dtype", "shape", "data"}`` arrays)
go through :func:`pack_state` / :func:`unpack_state`: arrays binary, the rest JSON.
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

_STATE_META = "__state__"


def pack(arrays: Mapping[str, np.ndarray], *, compress: bool = False) -> bytes:
    buffer = io.BytesIO()
    saver = np.savez_compressed if compress else np.savez
    saver(buffer, **{name: np.asarray(a) for name, a in arrays.items()})
    return buffer.getvalue()


def unpack(blob: bytes) -> dict[str, np.ndarray]:
    with np.load(io.BytesIO(blob), allow_pickle=False) as f:
        return {name: np.array(f[name]) for name in f.files}


def pack_array(array: np.ndarray) -> bytes:
    return pack({"a": array})


def unpack_array(blob: bytes | None) -> np.ndarray | None:
    return None if blob is None else unpack(blob)["a"]


def pack_state(data: Mapping[str, Any]) -> bytes:
    """An estimator state's ``to_dict()`` output as npz: its arrays binary, the rest JSON."""
    arrays: dict[str, np.ndarray] = {}
    meta: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict) and {"dtype", "shape", "data"} <= set(value):
            arrays[key] = np.asarray(value["data"], dtype=value["dtype"]).reshape(value["shape"])
        else:
            meta[key] = value
    arrays[_STATE_META] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return pack(arrays)


def unpack_state(blob: bytes) -> dict[str, Any]:
    """The inverse of :func:`pack_state`: data for the state class's ``from_dict``."""
    arrays = unpack(blob)
    meta = json.loads(arrays.pop(_STATE_META).tobytes().decode())
    for key, a in arrays.items():
        meta[key] = {"dtype": str(a.dtype), "shape": list(a.shape), "data": a.ravel().tolist()}
    return meta


def pack_meta(arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> bytes:
    """Arrays plus a JSON document in one npz."""
    encoded = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return pack({**arrays, _STATE_META: encoded})


def unpack_meta(blob: bytes) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The inverse of :func:`pack_meta`; a blob of :func:`pack` has the document ``{}``."""
    arrays = unpack(blob)
    encoded = arrays.pop(_STATE_META, None)
    meta = {} if encoded is None else json.loads(encoded.tobytes().decode())
    return arrays, meta
