"""Parsed A2L files, kept twice: in memory (the last few, by content hash) and on disk.

Parsing a production A2L takes seconds (:func:`app.calibration.a2l.open_a2l` writes its
result to a cache directory keyed by the file's SHA-256), so every request that needs the
A2L of an ECU goes through :func:`open_cached`: a hit in memory answers at once, a hit on
disk in well under a second, a miss parses once; a hit never waits for a parse in progress.
The disk cache is bounded: after each parse the oldest entries go until at most
``max_files`` files and ``max_bytes`` bytes remain (``MAPWISE_CACHE_FILES``,
``MAPWISE_CACHE_MB``; docs/calibration.md#rest-and-cli).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from app.calibration.a2l import A2lFile

MEMORY_ENTRIES = 4  # parsed A2L objects kept per process (a 2 MB A2L holds a few MB)

_memory: OrderedDict[str, A2lFile] = OrderedDict()
_memory_lock = threading.Lock()
_parse_lock = threading.Lock()  # one parse at a time; hits never take it (open_cached)


@dataclass(frozen=True, slots=True)
class CacheLimits:
    """Where the disk cache lives and how much it may hold."""

    directory: Path
    max_files: int
    max_bytes: int


def sha256_of(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def open_cached(sha256: str, load: Callable[[], bytes], limits: CacheLimits) -> A2lFile:
    """The parsed A2L whose content hash is ``sha256``; ``load`` gives its bytes on a miss.

    A hit in memory or on disk never waits: only a parse takes ``_parse_lock`` (parses run
    one at a time, each a child process holding the whole file), so reopening a cached A2L
    does not queue behind another A2L's 10–40 s parse. Under the lock the disk is checked
    again, so two requests for one new A2L parse it once."""
    hit = _remember(sha256)
    if hit is not None:
        return hit
    hit = _from_disk(sha256, limits)
    if hit is None:
        with _parse_lock:
            hit = _from_disk(sha256, limits)  # parsed while this request waited
            if hit is None:
                from app.calibration.a2l import open_a2l

                limits.directory.mkdir(parents=True, exist_ok=True)
                hit = open_a2l(load(), cache_dir=limits.directory)
                prune(limits, keep=sha256)
    _touch(limits.directory, sha256)
    with _memory_lock:
        _memory[sha256] = hit
        _memory.move_to_end(sha256)
        while len(_memory) > MEMORY_ENTRIES:
            _memory.popitem(last=False)
    return hit


def open_bytes(data: bytes, limits: CacheLimits) -> A2lFile:
    """:func:`open_cached` for bytes in hand (an upload, a file given to the CLI)."""
    return open_cached(sha256_of(data), lambda: data, limits)


def _remember(sha256: str) -> A2lFile | None:
    with _memory_lock:
        a2l = _memory.get(sha256)
        if a2l is not None:
            _memory.move_to_end(sha256)
        return a2l


def _from_disk(sha256: str, limits: CacheLimits) -> A2lFile | None:
    """The A2L from the disk cache, ``None`` when it is not there (no parse, no lock)."""
    from app.calibration.a2l import open_cached as open_from_disk

    return open_from_disk(sha256, cache_dir=limits.directory)


def _entries(directory: Path) -> list[Path]:
    try:
        return [p for p in directory.iterdir() if not p.name.startswith(".")]
    except FileNotFoundError:
        return []


def _size(path: Path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _files(path: Path) -> int:
    return sum(1 for p in path.rglob("*") if p.is_file()) if path.is_dir() else 1


def _touch(directory: Path, sha256: str) -> None:
    """Mark the entries of ``sha256`` as just used (eviction goes by modification time)."""
    for path in _entries(directory):
        if path.name.startswith(sha256):
            with contextlib.suppress(OSError):
                os.utime(path)


def prune(limits: CacheLimits, *, keep: str = "") -> int:
    """Delete the least recently used entries (files or directories named after a content
    hash) until the cache holds at most ``max_files`` files and ``max_bytes`` bytes; the
    entries of ``keep`` stay. Returns how many entries went."""
    import shutil

    entries = []
    for path in _entries(limits.directory):
        try:
            entries.append((path.stat().st_mtime, path, _size(path), _files(path)))
        except OSError:  # removed meanwhile by another process
            continue
    entries.sort(key=lambda e: e[0])
    total_bytes = sum(e[2] for e in entries)
    total_files = sum(e[3] for e in entries)
    removed = 0
    for _, path, size, files in entries:
        if total_bytes <= limits.max_bytes and total_files <= limits.max_files:
            break
        if keep and path.name.startswith(keep):
            continue
        try:
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        except OSError:
            continue
        total_bytes -= size
        total_files -= files
        removed += 1
    return removed


def forget() -> None:
    """Drop the in-memory entries (tests: the next open reads the disk cache)."""
    with _memory_lock:
        _memory.clear()
