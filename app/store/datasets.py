"""Datasets' samples in the store: staged to a file, stored under a key, loaded and verified.

A dataset's object is ``datasets/<id>-<sha16>-<nonce>.parquet`` (:func:`dataset_key`); the
database row keeps the key and the file's SHA-256. Loading streams the object through the
hash, then, through the same handle, decodes only the channels asked for
(:mod:`app.store.parquet_signals`, column projection): a changed or truncated file never
reaches an estimator, and a run holds only the channels it uses, never the file's bytes.
The nonce keeps two databases sharing a store (a restored backup, a test suite) from ever
writing or deleting each other's objects.

A dataset stored *as recorded* (its channels on their own timestamps, :func:`stage_recorded`)
is put on one raster when it is read: the channels asked for, with
:func:`app.io.resample.resample`, on the raster asked for, by default the slowest among
*those* channels (`docs/data-formats.md#multi-rate`). A dense dataset is read as stored.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import secrets
import tempfile
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pyarrow as pa

from app.domain import Channel, StoredSamples
from app.io.errors import InputError
from app.io.ingest import IngestLimits
from app.io.resample import Raster, Track, resample
from app.store.errors import ArtifactCorruptError, ArtifactMissingError
from app.store.objects import ArtifactStore
from app.store.parquet_signals import (
    HASH_CHUNK,
    Column,
    SignalsFile,
    write_columns,
    write_recorded,
)
from estimation.signals import Signals

log = logging.getLogger("mapwise.store")


@dataclass(frozen=True, slots=True)
class StagedDataset:
    """A Parquet file written and hashed, not yet in the store."""

    path: Path
    sha256: str


def dataset_key(dataset_id: int, sha256: str) -> str:
    return f"datasets/{dataset_id}-{sha256[:16]}-{secrets.token_hex(4)}.parquet"


@contextlib.contextmanager
def stage_signals(store: ArtifactStore, signals: Signals) -> Iterator[StagedDataset]:
    """Write ``signals`` as Parquet to a temporary file (removed on exit unless stored)."""
    channels = [Column(n, signals.units.get(n, ""), signals[n]) for n in signals.names]
    with staging_file(store) as path:
        yield StagedDataset(path, write_columns(path, signals.time, channels))


@contextlib.contextmanager
def stage_recorded(
    store: ArtifactStore, tracks: Sequence[Track], units: dict[str, str]
) -> Iterator[StagedDataset]:
    """Write channels recorded on their own timestamps as one Parquet file as recorded
    (:func:`~app.store.parquet_signals.write_recorded`), with their hold flags; ``units``
    by channel name (those after the upload's overrides)."""
    pairs = [
        (Column(t.name, units.get(t.name, t.unit), t.values, hold=t.hold), t.time) for t in tracks
    ]
    with staging_file(store) as path:
        yield StagedDataset(path, write_recorded(path, pairs))


@contextlib.contextmanager
def stage_columns(
    store: ArtifactStore, time: np.ndarray, channels: Sequence[Column]
) -> Iterator[StagedDataset]:
    """:func:`stage_signals` for raw arrays (the migration of npz payloads)."""
    with staging_file(store) as path:
        yield StagedDataset(path, write_columns(path, time, channels))


@contextlib.contextmanager
def staging_file(store: ArtifactStore) -> Iterator[Path]:
    fd, name = tempfile.mkstemp(prefix=".dataset-", suffix=".parquet", dir=store.staging_dir())
    os.close(fd)
    path = Path(name)
    try:
        yield path
    finally:
        path.unlink(missing_ok=True)


def save_staged(store: ArtifactStore, dataset_id: int, staged: StagedDataset) -> str:
    """Put the staged file in the store under a new key for ``dataset_id``; the key."""
    key = dataset_key(dataset_id, staged.sha256)
    store.put_file(key, staged.path)
    return key


@contextlib.contextmanager
def open_verified(
    store: ArtifactStore, dataset_id: int, key: str, sha256: str
) -> Iterator[BinaryIO]:
    """The object, open for reading at its start, after checking its bytes hash to ``sha256``.

    The hash streams over the file in blocks (:data:`HASH_CHUNK`), so checking a file never
    holds it; the caller then reads what it needs through the same handle. A dataset's key
    is never written twice (each put has a new nonce) and, on a local disk, an open handle
    keeps the file it opened, so what is decoded is what was hashed.
    """
    where = store.location(key)
    try:
        f = store.open(key)
    except FileNotFoundError as exc:
        raise ArtifactMissingError(
            f"dataset {dataset_id}: its samples {key} are missing from the store ({where})",
            field="dataset_id",
        ) from exc
    with f:
        digest = hashlib.sha256()
        while block := f.read(HASH_CHUNK):
            digest.update(block)
        actual = digest.hexdigest()
        if actual != sha256:
            raise ArtifactCorruptError(
                f"dataset {dataset_id}: its samples {key} in the store ({where}) have SHA-256 "
                f"{actual[:16]}…, not the {sha256[:16]}… stored with the dataset",
                field="dataset_id",
            )
        f.seek(0)
        yield f


@contextlib.contextmanager
def open_signals(
    store: ArtifactStore,
    dataset_id: int,
    key: str,
    sha256: str,
    *,
    expect: Sequence[str] | None = None,
) -> Iterator[SignalsFile]:
    """The verified object (:func:`open_verified`) opened as a :class:`SignalsFile`: one that
    cannot be decoded, or whose channels are not exactly ``expect`` in that order, raises
    :class:`ArtifactCorruptError` (right hash, wrong content: written by a bad writer)."""
    with open_verified(store, dataset_id, key, sha256) as f:
        try:
            file = SignalsFile.open(f)
        except (ValueError, OSError, pa.ArrowException) as exc:
            raise _undecodable(dataset_id, key, exc) from exc
        stored = [name for name, _ in file.channels]
        if expect is not None and stored != list(expect):
            raise ArtifactCorruptError(
                f"dataset {dataset_id}: its samples {key} hold channels {stored}, "
                f"not the dataset's {list(expect)}",
                field="dataset_id",
            )
        yield file


def _undecodable(dataset_id: int, key: str, exc: Exception) -> ArtifactCorruptError:
    return ArtifactCorruptError(
        f"dataset {dataset_id}: its samples {key} cannot be decoded: {exc}", field="dataset_id"
    )


def load_columns(
    store: ArtifactStore,
    dataset_id: int,
    key: str,
    sha256: str,
    names: Collection[str] | None = None,
    *,
    expect: Sequence[str] | None = None,
) -> tuple[np.ndarray, list[Column]]:
    """The verified object's time and channel columns: those in ``names`` (default all), in
    the file's order, the others never read. With ``expect``, the file's channels must be
    exactly those names in that order (ArtifactCorruptError otherwise)."""
    with open_signals(store, dataset_id, key, sha256, expect=expect) as file:
        try:
            return file.read(names)
        except (ValueError, OSError, pa.ArrowException) as exc:
            raise _undecodable(dataset_id, key, exc) from exc


@dataclass(frozen=True, slots=True)
class LoadedSignals:
    """Samples read for a use: ``raster`` describes the raster a dataset stored as recorded
    was put on (``None``: a dense dataset, read as stored) and ``step_s`` its median step."""

    signals: Signals
    raster: str | None = None
    step_s: float | None = None


def load_signals(
    store: ArtifactStore,
    stored: StoredSamples,
    channels: Sequence[Channel],
    names: Collection[str] | None = None,
    *,
    raster: Raster | None = None,
) -> Signals:
    """The dataset's samples, with the channels' names, order and units of its row; only
    the channels in ``names`` (default all; a name the dataset lacks is ignored, so the
    estimator's own check names it). A dataset stored as recorded is resampled
    (:func:`load_on_raster`)."""
    return load_on_raster(store, stored, channels, names, raster=raster).signals


def load_on_raster(
    store: ArtifactStore,
    stored: StoredSamples,
    channels: Sequence[Channel],
    names: Collection[str] | None = None,
    *,
    raster: Raster | None = None,
) -> LoadedSignals:
    """:func:`load_signals` and the raster used. A dataset stored as recorded has its
    channels in ``names`` put on ``raster`` (default: the slowest among them, the rules of
    `docs/data-formats.md#multi-rate`); a raster that cannot be made (a channel it does not
    read, too many rows) raises :class:`~app.io.errors.InputError`."""
    dataset_id, key = stored.dataset_id, stored.key
    expect = [c.name for c in channels]
    time, columns = load_columns(store, dataset_id, key, stored.sha256, names, expect=expect)
    units = {c.name: c.unit for c in channels}
    if not columns or columns[0].present is None:
        by_name = {c.name: c.values for c in columns}
        del columns
        return LoadedSignals(Signals(time, by_name, {n: units[n] for n in by_name}, copy=False))
    tracks = [
        Track(c.name, units[c.name], time[c.present], c.values[c.present], c.hold) for c in columns
    ]
    del columns, time
    limits = IngestLimits()
    try:
        table = resample(
            tracks, raster or Raster(), max_rows=limits.max_rows, max_values=limits.max_values
        )
    except InputError as exc:
        raise InputError(f"dataset {dataset_id}: {exc}", field=exc.field) from None
    step = float(np.median(np.diff(table.time))) if table.time.size > 1 else None
    used = table.raster or Raster(channel=tracks[0].name)  # None: one shared time base
    described = used.describe()
    return LoadedSignals(
        Signals(table.time, table.channels, table.units, copy=False), described, step
    )


def delete_dataset(store: ArtifactStore, dataset_id: int, key: str) -> bool:
    """Remove the dataset's object, after its row is gone; a failure is logged, not raised
    (an orphaned object wastes space, a failed request after the commit would lie)."""
    try:
        store.delete(key)
        return True
    except FileNotFoundError:
        return True
    except Exception as exc:
        log.warning(
            "dataset %s deleted, but its object %s stayed in the store: %s",
            dataset_id,
            store.location(key),
            exc,
        )
        return False
