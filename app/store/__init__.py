"""The artifact store: datasets' samples as Parquet objects beside the database.

The database keeps each dataset's metadata, its object key and the object's SHA-256; the
samples live in the store at ``MAPWISE_STORE_URL`` (a local directory or any fsspec URL).
docs/data-formats.md#stored-datasets describes the layout.
"""

from app.store.datasets import (
    LoadedSignals,
    StagedDataset,
    dataset_key,
    delete_dataset,
    load_columns,
    load_on_raster,
    load_signals,
    open_verified,
    save_staged,
    stage_columns,
    stage_recorded,
    stage_signals,
    staging_file,
)
from app.store.errors import ArtifactCorruptError, ArtifactError, ArtifactMissingError
from app.store.location import DEFAULT_STORE_URL, default_store_url, resolve_store_url
from app.store.objects import ArtifactStore, open_store

__all__ = [
    "DEFAULT_STORE_URL",
    "ArtifactCorruptError",
    "ArtifactError",
    "ArtifactMissingError",
    "ArtifactStore",
    "LoadedSignals",
    "StagedDataset",
    "dataset_key",
    "default_store_url",
    "delete_dataset",
    "load_columns",
    "load_on_raster",
    "load_signals",
    "open_store",
    "open_verified",
    "resolve_store_url",
    "save_staged",
    "stage_columns",
    "stage_recorded",
    "stage_signals",
    "staging_file",
]
