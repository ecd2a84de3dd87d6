"""The two wire encodings of a live frame (``WS /api/runs/{id}/stream?encoding=``).

``json`` (the default): the frame's JSON document as one text message, NaN as ``null``.

``binary`` (opt-in, what the dashboard asks for): one binary message laid out as

====== ======== ==========================================================================
offset size     content
====== ======== ==========================================================================
0      4        magic ``b"MWLF"`` (mapwise live frame)
4      1        layout version, ``1``
5      3        zero
8      4        ``n``: length of the JSON part in bytes, uint32 little-endian
12     n        the JSON part, UTF-8: ``{"frame": FRAME, "arrays": [REF, ...]}``
12 + n 0–7      zero padding, so the data block starts at a multiple of 8
…      …        the data block: each array little-endian, C order, at a multiple of 8
====== ======== ==========================================================================

``FRAME`` is the JSON frame with each big array set to ``null``; every ``REF`` is
``{"path": [key, ...], "dtype": "f32" | "f64", "offset": bytes from the data block's start,
"shape": [d0, ...]}`` and puts its array back at ``path`` (e.g. ``["series", "u1",
"values"]``). The big arrays are the maps (``values``, ``variances``, ``visits``), the
trajectory's ``points`` and each series' ``values`` as float32, and the times
(``trajectory.time``, each series' ``time``) as float64: a log's time may be absolute (s
since the epoch), which float32 resolves to 128 s only. NaN travels as NaN (the JSON
frame's ``null``); the JSON part stays strict JSON. An array that is not rectangular and
numeric stays in the JSON part.
"""

from __future__ import annotations

import json
import struct
from typing import Any, Literal

import numpy as np

Encoding = Literal["json", "binary"]
ENCODINGS: tuple[Encoding, ...] = ("json", "binary")
MAGIC = b"MWLF"
VERSION = 1
HEADER = struct.Struct("<4sB3xI")  # magic, version, padding, JSON length
ALIGN = 8
MAP_KEYS = ("values", "variances", "visits")
DTYPES = {"f32": np.dtype("<f4"), "f64": np.dtype("<f8")}

Json = dict[str, Any]


def encode(frame: Json, encoding: Encoding) -> str | bytes:
    """The frame as one WebSocket message: text for ``json``, bytes for ``binary``."""
    return encode_json(frame) if encoding == "json" else encode_binary(frame)


def encode_json(frame: Json) -> str:
    return json.dumps(frame, separators=(",", ":"))


def encode_binary(frame: Json) -> bytes:
    """The binary layout of the module docstring."""
    doc, arrays = _split(frame)
    refs, chunks, offset = [], [], 0
    for path, dtype, array in arrays:
        data = array.astype(DTYPES[dtype], copy=False).tobytes()
        refs.append({"path": path, "dtype": dtype, "offset": offset, "shape": list(array.shape)})
        chunks.append(data + bytes(-len(data) % ALIGN))
        offset += len(chunks[-1])
    head = encode_json({"frame": doc, "arrays": refs}).encode()
    pad = bytes(-(HEADER.size + len(head)) % ALIGN)
    return b"".join([HEADER.pack(MAGIC, VERSION, len(head)), head, pad, *chunks])


def decode_binary(message: bytes) -> Json:
    """The frame from its binary layout, each array a numpy array (NaN where JSON has
    ``null``); ``ValueError`` if the message is not this layout."""
    if len(message) < HEADER.size:
        raise ValueError("binary frame: shorter than its header")
    magic, version, length = HEADER.unpack_from(message)
    if magic != MAGIC or version != VERSION:
        raise ValueError(f"binary frame: magic {magic!r} version {version}, not MWLF 1")
    end = HEADER.size + length
    head = json.loads(message[HEADER.size : end])
    start = end + (-end % ALIGN)
    frame = head["frame"]
    for ref in head["arrays"]:
        shape = tuple(int(d) for d in ref["shape"])
        count = int(np.prod(shape, dtype=np.int64))
        array = np.frombuffer(
            message, dtype=DTYPES[ref["dtype"]], count=count, offset=start + int(ref["offset"])
        )
        _put(frame, ref["path"], array.reshape(shape))
    return frame


def _split(frame: Json) -> tuple[Json, list[tuple[list[str], str, np.ndarray]]]:
    """The frame with its big arrays set to ``None`` (containers copied, never changed in
    place: the caller's frame may be encoded again) and the arrays taken out."""
    doc = dict(frame)
    arrays: list[tuple[list[str], str, np.ndarray]] = []

    def take(container: Json, key: str, path: list[str], dtype: str) -> None:
        array = _rectangular(container.get(key))
        if array is not None:
            container[key] = None
            arrays.append((path, dtype, array))

    for key in MAP_KEYS:
        take(doc, key, [key], "f32")
    if isinstance(doc.get("trajectory"), dict):
        doc["trajectory"] = trajectory = dict(doc["trajectory"])
        take(trajectory, "time", ["trajectory", "time"], "f64")
        take(trajectory, "points", ["trajectory", "points"], "f32")
    if isinstance(doc.get("series"), dict):
        doc["series"] = series = {}
        for name, line in frame["series"].items():
            series[name] = line = dict(line) if isinstance(line, dict) else line
            if isinstance(line, dict):
                take(line, "time", ["series", name, "time"], "f64")
                take(line, "values", ["series", name, "values"], "f32")
    return doc, arrays


def _rectangular(value: Any) -> np.ndarray | None:
    """A non-empty list (or array) of numbers and ``None`` (NaN) of one shape, else ``None``."""
    if not isinstance(value, list | np.ndarray) or len(value) == 0:
        return None
    try:
        array = np.asarray(value, dtype=np.float64)
    except (ValueError, TypeError):  # ragged, or not numbers
        return None
    return array if array.size else None


def _put(frame: Json, path: list[str], array: np.ndarray) -> None:
    target = frame
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = array
