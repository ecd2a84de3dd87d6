"""A run's log as rows read on demand: ``rows(a, z)`` is its samples ``a … z−1``.

:class:`MemoryRows` slices a log held whole. :class:`StoredRows` reads a dense dataset's
Parquet object (:mod:`app.store.parquet_signals`) a row group at a time, only the channels
the run uses, and keeps the last :data:`CACHED_GROUPS` groups decoded, so a streamed run
(`docs/data-formats.md#streamed-runs`) holds a window of the log, never the whole of it;
the live view and the stored series read the rows the estimator has just read from that
cache; :class:`~app.store.raster_rows.RasterRows` does the same for a dataset stored as
recorded, on a raster. :func:`open_rows` checks the object's hash first
(:func:`open_verified`) and keeps its handle open while the run reads.
"""

from __future__ import annotations

import contextlib
from collections import OrderedDict
from collections.abc import Collection, Iterator, Sequence
from typing import Protocol

import numpy as np
import pyarrow as pa

from app.domain import Channel, StoredSamples
from app.io.arrow_arrays import float64_values
from app.io.errors import InputError
from app.io.ingest import IngestLimits
from app.io.resample import Raster, Span
from app.store.datasets import open_signals
from app.store.errors import ArtifactCorruptError
from app.store.objects import ArtifactStore
from app.store.parquet_signals import SignalsFile
from app.store.raster_rows import RasterRows
from estimation.signals import Signals

CACHED_GROUPS = 8  # 8 × 65 536 rows of the channels read: 16 MiB for time and three channels


class LogRows(Protocol):
    """A log of ``n`` samples with channels ``names`` (units ``units``), read by rows."""

    n: int
    names: list[str]
    units: dict[str, str]

    def rows(self, a: int, z: int) -> Signals: ...

    def time(self) -> np.ndarray:
        """The whole time column (8 bytes a sample): a delay in seconds needs the log's
        sample period."""
        ...


class MemoryRows:
    """Rows of a log held whole."""

    def __init__(self, signals: Signals) -> None:
        self.signals = signals
        self.n = len(signals)
        self.names = list(signals.names)
        self.units = dict(signals.units)

    def rows(self, a: int, z: int) -> Signals:
        s = self.signals
        channels = {name: s[name][a:z] for name in self.names}
        return Signals(s.time[a:z], channels, self.units, copy=False)

    def time(self) -> np.ndarray:
        return self.signals.time


class StoredRows:
    """Rows of a dense dataset's object, read a row group at a time (module docstring)."""

    def __init__(self, file: SignalsFile, names: Sequence[str], units: dict[str, str]) -> None:
        if file.recorded:
            raise ValueError("a dataset stored as recorded is read on a raster (RasterRows)")
        self.file = file
        stored = [name for name, _ in file.channels]
        self.names = [name for name in stored if name in set(names)]
        self.units = {name: units[name] for name in self.names}
        self.fields = [file.time_name, *self.names]
        meta = file.reader.metadata
        sizes = [meta.row_group(g).num_rows for g in range(meta.num_row_groups)]
        self.starts = np.concatenate([[0], np.cumsum(sizes, dtype=np.int64)])
        self.n = int(self.starts[-1])
        self.cache: OrderedDict[int, list[np.ndarray]] = OrderedDict()

    def rows(self, a: int, z: int) -> Signals:
        a, z = max(0, a), min(self.n, z)
        if z <= a:
            empty = np.empty(0)
            return Signals(empty, dict.fromkeys(self.names, empty), self.units, copy=False)
        first = int(np.searchsorted(self.starts, a, side="right")) - 1
        last = int(np.searchsorted(self.starts, z, side="left"))
        groups = [self._group(g) for g in range(first, last)]
        lo, hi = a - int(self.starts[first]), z - int(self.starts[first])
        arrays = [
            parts[0][lo:hi] if len(parts) == 1 else np.concatenate(parts)[lo:hi]
            for parts in zip(*groups, strict=True)
        ]
        channels = dict(zip(self.names, arrays[1:], strict=True))
        return Signals(arrays[0], channels, self.units, copy=False)

    def time(self) -> np.ndarray:
        """The time column, read a row group at a time past the cache (only it decoded)."""
        out = np.empty(self.n)
        for g in range(len(self.starts) - 1):
            out[self.starts[g] : self.starts[g + 1]] = self._decode(g, [self.file.time_name])[0]
        return out

    def _group(self, g: int) -> list[np.ndarray]:
        if g in self.cache:
            self.cache.move_to_end(g)
            return self.cache[g]
        arrays = self._decode(g, self.fields)
        self.cache[g] = arrays
        while len(self.cache) > CACHED_GROUPS:
            self.cache.popitem(last=False)
        return arrays

    def _decode(self, g: int, fields: list[str]) -> list[np.ndarray]:
        try:
            table = self.file.reader.read_row_group(g, columns=fields, use_threads=False)
            return [_floats(table.column(k)) for k in range(len(fields))]
        except (OSError, ValueError, pa.ArrowException) as exc:
            raise ArtifactCorruptError(f"row group {g} cannot be decoded: {exc}") from exc


def _floats(column: pa.ChunkedArray) -> np.ndarray:
    if column.null_count:
        raise ValueError(f"a column has {column.null_count} missing values")
    chunks = [float64_values(chunk) for chunk in column.chunks]
    return chunks[0] if len(chunks) == 1 else np.concatenate(chunks)


@contextlib.contextmanager
def open_rows(
    store: ArtifactStore,
    stored: StoredSamples,
    channels: Sequence[Channel],
    names: Collection[str],
    *,
    raster: Raster | None = None,
) -> Iterator[StoredRows | RasterRows]:
    """The dataset's object as rows of the channels ``names`` (those it has), its hash
    checked first and its channels those of the dataset's row (:func:`open_signals`):
    :class:`StoredRows` for a dense dataset, :class:`~app.store.raster_rows.RasterRows` on
    ``raster`` (default: the slowest channel's) for one stored as recorded, whose
    :class:`~app.io.errors.InputError` names the dataset as :func:`load_on_raster`'s does."""
    expect = [c.name for c in channels]
    units = {c.name: c.unit for c in channels}
    with open_signals(store, stored.dataset_id, stored.key, stored.sha256, expect=expect) as file:
        if not file.recorded:
            yield StoredRows(file, list(names), units)
            return
        spans = {c.name: Span(c.name, *c.timing) for c in channels if c.timing is not None}
        limits = IngestLimits()
        try:
            rows = RasterRows(
                file,
                list(names),
                units,
                spans,
                raster,
                max_rows=limits.max_rows,
                max_values=limits.max_values,
            )
        except InputError as exc:
            raise InputError(f"dataset {stored.dataset_id}: {exc}", field=exc.field) from None
        yield rows
