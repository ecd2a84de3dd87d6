"""Objects under the store's root, by key (``datasets/12-….parquet``), through fsspec.

A put never leaves a partial object under its final key: the bytes go to a hidden temporary
key in the same directory first, then are moved into place (a rename on a local disk; on an
object store, where a move is a copy, the copy appears whole or not at all). Reads take an
object whole (:meth:`read_bytes`) or through a handle (:meth:`open`, for a hash and a
decoding in one pass each without holding the bytes).
"""

from __future__ import annotations

import os
import secrets
from functools import lru_cache
from pathlib import Path
from typing import BinaryIO

import fsspec
from fsspec.implementations.local import LocalFileSystem

from app.store.location import default_store_url, redacted, resolve_store_url

STAGING = ".staging"  # a local store's files being written, moved into place when done


class ArtifactStore:
    """The store at ``url`` (as :func:`resolve_store_url` gives it)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.fs, root = fsspec.core.url_to_fs(url)
        self.root = root.rstrip("/")
        self.local = isinstance(self.fs, LocalFileSystem)
        # fsspec's memory:// lives in this process: another one sees an empty store there
        self.shared = "memory" not in self.fs.protocol

    def path(self, key: str) -> str:
        return f"{self.root}/{key}"

    def location(self, key: str) -> str:
        """The object's URL without credentials, for messages."""
        return f"{redacted(self.url).rstrip('/')}/{key}"

    def staging_dir(self) -> Path | None:
        """Where to write a file before :meth:`put_file`: inside a local store's root (so the
        put is a rename, never a copy), else ``None`` (the system's temporary directory)."""
        if not self.local:
            return None
        staging = Path(self.root) / STAGING
        staging.mkdir(parents=True, exist_ok=True)
        return staging

    def put_file(self, key: str, local_path: str | os.PathLike[str]) -> None:
        """Store the local file under ``key``, replacing any object there; a file in
        :meth:`staging_dir` is moved (renamed), any other copied."""
        final = self.path(key)
        directory, name = final.rsplit("/", 1)
        self.fs.makedirs(directory, exist_ok=True)
        if self.local and Path(local_path).parent == Path(self.root) / STAGING:
            os.replace(local_path, final)  # atomic on POSIX: same filesystem
            return
        temporary = f"{directory}/.{name}.{secrets.token_hex(6)}.tmp"
        try:
            self.fs.put_file(str(local_path), temporary)
            if self.local:
                os.replace(temporary, final)
            else:
                self.fs.mv(temporary, final)
        except BaseException:
            self._discard(temporary)
            raise

    def open(self, key: str) -> BinaryIO:
        """The object, open for binary reading; FileNotFoundError when there is none."""
        return self.fs.open(self.path(key), "rb")

    def read_bytes(self, key: str) -> bytes:
        """The whole object; FileNotFoundError when there is none."""
        with self.fs.open(self.path(key), "rb") as f:
            return f.read()

    def exists(self, key: str) -> bool:
        return bool(self.fs.exists(self.path(key)))

    def delete(self, key: str) -> None:
        """Remove the object (FileNotFoundError when there is none)."""
        self.fs.rm_file(self.path(key))

    def _discard(self, path: str) -> None:
        try:
            if self.fs.exists(path):
                self.fs.rm_file(path)
        except Exception:  # the original failure matters more than the leftover
            pass


def open_store(url: str | None = None) -> ArtifactStore:
    """The store at ``url`` (default: ``MAPWISE_STORE_URL``, else ``./mapwise-data/``), one
    instance per URL and process."""
    return _store(default_store_url() if url is None else resolve_store_url(url))


@lru_cache(maxsize=16)
def _store(url: str) -> ArtifactStore:
    return ArtifactStore(url)
