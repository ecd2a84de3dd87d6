"""Datasets' samples in the store: staged to a file, stored under a key, loaded and verified.

A dataset's object is ``datasets/<id>-<sha16>-<nonce>.parquet`` (:func:`dataset_key`); the
database row keeps the key and the file's SHA-256. Loading reads the object once, checks the
hash, then decodes it (:mod:`app.store.parquet_signals`), so a changed or truncated file never
reaches an estimator. The nonce keeps two databases sharing a store (a restored backup, a
test suite) from ever writing or deleting each other's objects.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import secrets
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.domain import Channel, StoredSamples
from app.store.errors import ArtifactCorruptError, ArtifactMissingError
from app.store.objects import ArtifactStore
from app.store.parquet_signals import Column, read_columns, write_columns
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
    with _staging_file(store) as path:
        yield StagedDataset(path, write_columns(path, signals.time, channels))


@contextlib.contextmanager
def stage_columns(
    store: ArtifactStore, time: np.ndarray, channels: Sequence[Column]
) -> Iterator[StagedDataset]:
    """:func:`stage_signals` for raw arrays (the migration of npz payloads)."""
    with _staging_file(store) as path:
        yield StagedDataset(path, write_columns(path, time, channels))


@contextlib.contextmanager
def _staging_file(store: ArtifactStore) -> Iterator[Path]:
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


def read_verified(store: ArtifactStore, dataset_id: int, key: str, sha256: str) -> bytes:
    """The object's bytes, after checking they hash to ``sha256``."""
    where = store.location(key)
    try:
        data = store.read_bytes(key)
    except FileNotFoundError as exc:
        raise ArtifactMissingError(
            f"dataset {dataset_id}: its samples {key} are missing from the store ({where})",
            field="dataset_id",
        ) from exc
    actual = hashlib.sha256(data).hexdigest()
    if actual != sha256:
        raise ArtifactCorruptError(
            f"dataset {dataset_id}: its samples {key} in the store ({where}) have SHA-256 "
            f"{actual[:16]}…, not the {sha256[:16]}… stored with the dataset",
            field="dataset_id",
        )
    return data


def load_columns(
    store: ArtifactStore, dataset_id: int, key: str, sha256: str
) -> tuple[np.ndarray, list[Column]]:
    """The verified object's time and channel columns."""
    data = read_verified(store, dataset_id, key, sha256)
    try:
        return read_columns(data)
    except (ValueError, OSError) as exc:  # right hash, wrong content: written by a bad writer
        raise ArtifactCorruptError(
            f"dataset {dataset_id}: its samples {key} cannot be decoded: {exc}",
            field="dataset_id",
        ) from exc


def load_signals(
    store: ArtifactStore, stored: StoredSamples, channels: Sequence[Channel]
) -> Signals:
    """The dataset's samples, with the channels' names, order and units of its row."""
    dataset_id, key = stored.dataset_id, stored.key
    time, columns = load_columns(store, dataset_id, key, stored.sha256)
    names = [c.name for c in columns]
    if names != [c.name for c in channels]:
        raise ArtifactCorruptError(
            f"dataset {dataset_id}: its samples {key} hold channels {names}, "
            f"not the dataset's {[c.name for c in channels]}",
            field="dataset_id",
        )
    by_name = {c.name: c.values for c in columns}
    del columns
    return Signals(time, by_name, {c.name: c.unit for c in channels}, copy=False)


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
