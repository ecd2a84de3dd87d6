"""SQLite connection settings: every pooled connection gets them, whichever thread opens it."""

from __future__ import annotations

import _sqlite3
import ctypes
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from sqlalchemy import text

from app.db.engine import SQLITE_BUSY_TIMEOUT_MS, SQLITE_CACHE_KIB, Database


def test_every_sqlite_connection_has_wal_busy_timeout_foreign_keys_and_a_bounded_cache(
    tmp_path: Path,
) -> None:
    db = Database(f"sqlite:///{tmp_path / 'engine.db'}")

    def pragmas(_: int) -> tuple:
        with db.read() as s:
            return tuple(
                s.execute(text(f"PRAGMA {name}")).scalar()
                for name in ("journal_mode", "busy_timeout", "foreign_keys", "cache_size")
            )

    try:
        with ThreadPoolExecutor(8) as pool:  # several threads: several pooled connections
            seen = set(pool.map(pragmas, range(64)))
    finally:
        db.dispose()
    assert seen == {("wal", SQLITE_BUSY_TIMEOUT_MS, 1, -SQLITE_CACHE_KIB)}


def _sqlite_memory_used() -> int:
    """``sqlite3_memory_used()``: bytes SQLite itself holds in this process (its page caches
    among them), from the library the ``sqlite3`` module is linked with."""
    lib = ctypes.CDLL(_sqlite3.__file__)
    lib.sqlite3_memory_used.restype = ctypes.c_int64
    return int(lib.sqlite3_memory_used())


def test_pooled_connections_reading_a_large_database_hold_little_memory(tmp_path: Path) -> None:
    """Eight pooled connections each read an 8 MB table: SQLite's memory grows by about their
    bounded caches (8 × 256 KiB), not by 8 × SQLite's default 2 MiB."""
    db = Database(f"sqlite:///{tmp_path / 'big.db'}")
    try:
        with db.write() as s:
            s.execute(text("CREATE TABLE blobs (id INTEGER PRIMARY KEY, data BLOB)"))
            s.execute(
                text("INSERT INTO blobs (data) VALUES (:d)"),
                [{"d": bytes([i % 251]) * 4000} for i in range(2000)],
            )
        barrier = threading.Barrier(8)

        def read(_: int) -> int:
            with db.read() as s:
                barrier.wait()  # all eight sessions open at once: eight connections
                return int(s.execute(text("SELECT sum(length(data)) FROM blobs")).scalar())

        before = _sqlite_memory_used()
        with ThreadPoolExecutor(8) as pool:
            assert set(pool.map(read, range(8))) == {8_000_000}
        grown = _sqlite_memory_used() - before
    finally:
        db.dispose()
    assert grown < 8 * (SQLITE_CACHE_KIB * 1024 + 200_000), grown
