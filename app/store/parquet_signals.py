"""A dataset's samples as one Parquet file: a float64 time column, then one float64 column
per channel in the dataset's order, written in row groups of :data:`ROW_GROUP_ROWS`.

Each field's metadata holds its ``unit`` (the time's is ``s``) and its ``role`` (``time`` or
``channel``); the schema's ``mapwise`` metadata names the format and the time field. Columns
are stored plain (no dictionary) and zstd-compressed, so every value, including ``-0.0``,
reads back bit for bit. Any Parquet reader (pandas, DuckDB, Polars) opens the file.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

ROW_GROUP_ROWS = 65_536
FORMAT = "mapwise-signals/1"
SCHEMA_KEY = b"mapwise"
HASH_CHUNK = 1 << 20


@dataclass(frozen=True, slots=True)
class Column:
    name: str
    unit: str
    values: np.ndarray


def _time_field_name(channels: Sequence[Column]) -> str:
    """``time``, prefixed with ``_`` until no channel has the name."""
    names = {c.name for c in channels}
    name = "time"
    while name in names:
        name = f"_{name}"
    return name


def write_columns(
    path: str | os.PathLike[str], time: np.ndarray, channels: Sequence[Column]
) -> str:
    """Write the file at ``path``; returns the SHA-256 (hex) of its bytes."""
    time_name = _time_field_name(channels)
    fields = [_field(time_name, "s", "time")] + [
        _field(c.name, c.unit, "channel") for c in channels
    ]
    meta = {"format": FORMAT, "time": time_name, "rows": int(time.size)}
    schema = pa.schema(fields, metadata={SCHEMA_KEY: json.dumps(meta).encode()})
    arrays = [np.ascontiguousarray(time, dtype=np.float64)]
    arrays += [np.ascontiguousarray(c.values, dtype=np.float64) for c in channels]
    with pq.ParquetWriter(path, schema, compression="zstd", use_dictionary=False) as writer:
        for start in range(0, max(1, time.size), ROW_GROUP_ROWS):
            stop = start + ROW_GROUP_ROWS
            batch = pa.record_batch([pa.array(a[start:stop]) for a in arrays], schema=schema)
            writer.write_batch(batch, row_group_size=ROW_GROUP_ROWS)
    return file_sha256(path)


def _field(name: str, unit: str, role: str) -> pa.Field:
    return pa.field(name, pa.float64(), nullable=False, metadata={"unit": unit, "role": role})


def file_sha256(path: str | os.PathLike[str]) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(HASH_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def read_columns(data: bytes) -> tuple[np.ndarray, list[Column]]:
    """The time and the channels of a file's bytes (one column decoded at a time, so the
    peak is the file plus the arrays); ValueError when it is not this format."""
    reader = pq.ParquetFile(pa.BufferReader(data))
    schema = reader.schema_arrow
    meta = json.loads((schema.metadata or {}).get(SCHEMA_KEY, b"{}"))
    if meta.get("format") != FORMAT or schema.names[:1] != [meta.get("time")]:
        raise ValueError(f"not a {FORMAT} file (schema metadata {meta})")
    arrays = []
    for field in schema:
        column = reader.read(columns=[field.name], use_threads=False).column(0)
        arrays.append(np.ascontiguousarray(column.to_numpy(), dtype=np.float64))
    if any(a.size != meta["rows"] for a in arrays):
        raise ValueError(f"a column is not {meta['rows']} rows long")
    channels = [
        Column(f.name, (f.metadata or {}).get(b"unit", b"").decode(), a)
        for f, a in zip(list(schema)[1:], arrays[1:], strict=True)
    ]
    return arrays[0], channels
