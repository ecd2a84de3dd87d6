"""A dataset's samples as one Parquet file: a float64 time column, then one float64 column
per channel in the dataset's order, written in row groups of :data:`ROW_GROUP_ROWS`.

Each field's metadata holds its ``unit`` (the time's is ``s``) and its ``role`` (``time`` or
``channel``); the schema's ``mapwise`` metadata names the format and the time field. Columns
are stored plain (no dictionary) and zstd-compressed, so every value, including ``-0.0``,
reads back bit for bit. Any Parquet reader (pandas, DuckDB, Polars) opens the file.

A file *as recorded* (schema metadata ``"layout": "recorded"``, written by
:func:`write_recorded`) holds channels recorded on different timestamps: the time column is
the union of their timestamps and each channel is null where it has no sample (as a sparse
CSV export); NaN is a masked sample. Its channel fields are nullable and carry ``hold``
(``1``: held, previous value; ``0``: interpolated), `docs/data-formats.md#multi-rate`.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from app.io.arrow_arrays import float64_array, float64_values, valid_rows

ROW_GROUP_ROWS = 65_536
FORMAT = "mapwise-signals/1"
SCHEMA_KEY = b"mapwise"
HASH_CHUNK = 1 << 20


@dataclass(frozen=True, slots=True)
class Column:
    """A channel's values (NaN where masked); in a file as recorded, ``present`` marks the
    rows where it has a sample and ``hold`` says how it is resampled."""

    name: str
    unit: str
    values: np.ndarray
    present: np.ndarray | None = None
    hold: bool = False


def _time_field_name(channels: Sequence[Column]) -> str:
    """``time``, prefixed with ``_`` until no channel has the name."""
    names = {c.name for c in channels}
    name = "time"
    while name in names:
        name = f"_{name}"
    return name


class SignalsWriter:
    """A dense file written block by block (:func:`write_columns` in one go, a streamed
    upload as it is parsed): blocks of any length are cut into row groups of exactly
    :data:`ROW_GROUP_ROWS` rows, so the file does not depend on how its rows arrived, and
    the row count is put in the metadata when the file is closed (:meth:`close`)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        channels: Sequence[tuple[str, str]],
        rows: int | None = None,
    ) -> None:
        self.path = path
        time_name = _time_field_name([Column(n, u, np.empty(0)) for n, u in channels])
        fields = [_field(time_name, "s", "time")] + [_field(n, u, "channel") for n, u in channels]
        self.meta = {"format": FORMAT, "time": time_name}
        # rows known up front go into the schema too, where readers before the streamed
        # upload look for them; a streamed file has them only in the file's metadata
        known = self.meta if rows is None else self.meta | {"rows": rows}
        self.schema = pa.schema(fields, metadata={SCHEMA_KEY: json.dumps(known).encode()})
        self.writer = pq.ParquetWriter(path, self.schema, compression="zstd", use_dictionary=False)
        self.pending: list[list[np.ndarray]] = []  # blocks not yet in a row group
        self.buffered = 0
        self.rows = 0

    def write(self, time: np.ndarray, values: Sequence[np.ndarray]) -> None:
        """Append rows: their time and each channel's values, in the channels' order."""
        arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (time, *values)]
        self.pending.append(arrays)
        self.buffered += time.size
        while self.buffered >= ROW_GROUP_ROWS:
            self._flush(ROW_GROUP_ROWS)

    def close(self) -> str:
        """Write the last rows and the row count; the SHA-256 (hex) of the file's bytes."""
        if self.buffered or not self.rows:
            self._flush(self.buffered)
        self.writer.add_key_value_metadata(
            {SCHEMA_KEY: json.dumps(self.meta | {"rows": self.rows})}
        )
        self.writer.close()
        return file_sha256(self.path)

    def abort(self) -> None:
        self.writer.close()

    def _flush(self, rows: int) -> None:
        joined = [np.concatenate(parts) for parts in zip(*self.pending, strict=True)]
        if not joined:  # an empty file: one empty row group, as before
            joined = [np.empty(0) for _ in self.schema]
        batch = pa.record_batch([float64_array(a[:rows]) for a in joined], schema=self.schema)
        self.writer.write_batch(batch, row_group_size=ROW_GROUP_ROWS)
        self.pending = [[a[rows:] for a in joined]] if joined[0].size > rows else []
        self.buffered -= rows
        self.rows += rows


def write_columns(
    path: str | os.PathLike[str], time: np.ndarray, channels: Sequence[Column]
) -> str:
    """Write the file at ``path``; returns the SHA-256 (hex) of its bytes."""
    writer = SignalsWriter(path, [(c.name, c.unit) for c in channels], rows=int(time.size))
    for start in range(0, time.size, ROW_GROUP_ROWS):
        stop = start + ROW_GROUP_ROWS
        writer.write(time[start:stop], [c.values[start:stop] for c in channels])
    return writer.close()


def write_recorded(
    path: str | os.PathLike[str], tracks: Sequence[tuple[Column, np.ndarray]]
) -> str:
    """Write channels recorded on their own timestamps (``(column, time)`` pairs, each time
    strictly increasing) as one file as recorded: the union of the timestamps, each channel
    null on the rows where it has no sample. Returns the SHA-256 (hex) of its bytes."""
    columns = [c for c, _ in tracks]
    time = np.unique(np.concatenate([t for _, t in tracks]))
    time_name = _time_field_name(columns)
    fields = [_field(time_name, "s", "time")] + [
        _field(c.name, c.unit, "channel", hold=c.hold) for c in columns
    ]
    meta = {"format": FORMAT, "time": time_name, "rows": int(time.size), "layout": "recorded"}
    schema = pa.schema(fields, metadata={SCHEMA_KEY: json.dumps(meta).encode()})
    arrays = [time]
    masks = [np.zeros(time.size, dtype=bool)]
    for column, own in tracks:
        at = np.searchsorted(time, own)  # exact: every own time is in the union
        values = np.zeros(time.size, dtype=np.float64)
        values[at] = column.values
        absent = np.ones(time.size, dtype=bool)
        absent[at] = False
        arrays.append(values)
        masks.append(absent)
    with pq.ParquetWriter(path, schema, compression="zstd", use_dictionary=False) as writer:
        for start in range(0, max(1, time.size), ROW_GROUP_ROWS):
            stop = start + ROW_GROUP_ROWS
            batch = pa.record_batch(
                [
                    float64_array(a[start:stop], m[start:stop])
                    for a, m in zip(arrays, masks, strict=True)
                ],
                schema=schema,
            )
            writer.write_batch(batch, row_group_size=ROW_GROUP_ROWS)
    return file_sha256(path)


def _field(name: str, unit: str, role: str, *, hold: bool | None = None) -> pa.Field:
    if hold is None:
        return pa.field(name, pa.float64(), nullable=False, metadata={"unit": unit, "role": role})
    meta = {"unit": unit, "role": role, "hold": "1" if hold else "0"}
    return pa.field(name, pa.float64(), nullable=True, metadata=meta)


def file_sha256(path: str | os.PathLike[str]) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(HASH_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


@dataclass(frozen=True, slots=True)
class SignalsFile:
    """An open file of this format: its row count and channels (name, unit) in order, read
    from the footer; :meth:`read` decodes the time and the channels asked for."""

    reader: pq.ParquetFile
    time_name: str
    rows: int
    channels: list[tuple[str, str]]
    recorded: bool = False
    hold: frozenset[str] = frozenset()

    @classmethod
    def open(cls, source: pa.NativeFile | BinaryIO | bytes) -> SignalsFile:
        """ValueError when the file is not this format."""
        if isinstance(source, bytes | bytearray | memoryview):
            source = pa.BufferReader(source)
        reader = pq.ParquetFile(source, pre_buffer=False)
        schema = reader.schema_arrow
        # the file's key-value metadata: the schema's, or what a streamed writer put there
        # when it closed (the row count), which replaces it
        meta = json.loads((reader.metadata.metadata or {}).get(SCHEMA_KEY, b"{}"))
        if meta.get("format") != FORMAT or schema.names[:1] != [meta.get("time")]:
            raise ValueError(f"not a {FORMAT} file (schema metadata {meta})")
        if reader.metadata.num_rows != meta["rows"]:
            raise ValueError(f"the file has {reader.metadata.num_rows} rows, not {meta['rows']}")
        channels = [(f.name, (f.metadata or {}).get(b"unit", b"").decode()) for f in schema]
        recorded = meta.get("layout") == "recorded"
        hold = frozenset(f.name for f in schema if (f.metadata or {}).get(b"hold") == b"1")
        return cls(reader, meta["time"], int(meta["rows"]), channels[1:], recorded, hold)

    def read(self, names: Collection[str] | None = None) -> tuple[np.ndarray, list[Column]]:
        """The time and the channels in ``names`` (default: all), in the file's order.

        Only those columns' chunks are read and decompressed (column projection), one row
        group at a time into arrays allocated once: the peak is the arrays plus one row
        group of the chosen columns, whatever the file's other channels hold. In a file as
        recorded a channel's nulls are its rows without a sample (:attr:`Column.present`).
        """
        wanted = None if names is None else set(names)
        chosen = [c for c in self.channels if wanted is None or c[0] in wanted]
        fields = [self.time_name] + [name for name, _ in chosen]
        arrays = [np.empty(self.rows, dtype=np.float64) for _ in fields]
        present = [np.empty(self.rows, dtype=bool) for _ in chosen] if self.recorded else []
        start = 0
        batches = self.reader.iter_batches(
            batch_size=ROW_GROUP_ROWS, columns=fields, use_threads=False
        )
        for batch in batches:
            stop = start + batch.num_rows
            if stop > self.rows:
                raise ValueError(f"the columns are longer than {self.rows} rows")
            for k, (array, column) in enumerate(zip(arrays, batch.columns, strict=True)):
                if column.null_count and (k == 0 or not self.recorded):
                    raise ValueError(f"a column has {column.null_count} missing values")
                array[start:stop] = float64_values(column)
                if k > 0 and self.recorded:
                    valid = valid_rows(column)
                    present[k - 1][start:stop] = valid
                    array[start:stop][~valid] = np.nan  # as Arrow reads a null
            start = stop
        if start != self.rows:
            raise ValueError(f"the columns are {start} rows long, not {self.rows}")
        if not self.recorded:
            columns = [Column(n, u, a) for (n, u), a in zip(chosen, arrays[1:], strict=True)]
            return arrays[0], columns
        return arrays[0], [
            Column(n, u, a, p, n in self.hold)
            for (n, u), a, p in zip(chosen, arrays[1:], present, strict=True)
        ]


def read_columns(
    source: pa.NativeFile | BinaryIO | bytes, names: Collection[str] | None = None
) -> tuple[np.ndarray, list[Column]]:
    """The time and the channels (those in ``names``, default all) of a file or its bytes;
    ValueError when it is not this format."""
    return SignalsFile.open(source).read(names)
