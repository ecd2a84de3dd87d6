"""Revision 0008 on SQLite and PostgreSQL: every npz payload moves to the artifact store,
verified (hash and bits) before its blob is cleared; a payload that cannot move losslessly
aborts it with nothing changed; the downgrade puts the blobs back."""

from __future__ import annotations

import hashlib
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from alembic import command
from sqlalchemy import MetaData, inspect, select

from app.db import blobs
from app.db.engine import make_engine
from app.db.migrate import alembic_config, current_revision, upgrade
from app.domain import Channel, StoredSamples
from app.io.payload import pack_signals
from app.store import ArtifactStore, load_signals, open_store
from estimation.signals import Signals


def _signals(n: int, seed: int) -> Signals:
    rng = np.random.default_rng(seed)
    channels = {"speed_rpm": rng.uniform(800, 4000, n), "time": rng.normal(0.0, 1e-200, n)}
    channels["nox_ppm"] = np.where(rng.random(n) < 0.3, -0.0, rng.normal(90.0, 20.0, n))
    units = {"speed_rpm": "rpm", "time": "", "nox_ppm": "ppm"}
    return Signals(np.arange(n) / 50.0 + 1e-9 * seed, channels, units)


SAMPLES = {1: _signals(70_000, 1), 2: _signals(3, 2), 5: _signals(1000, 5)}


def _insert(url: str, rows: dict[int, bytes], channels: dict[int, list[dict[str, Any]]]) -> None:
    engine = make_engine(url)
    try:
        meta = MetaData()
        meta.reflect(engine, only=["datasets"])
        with engine.begin() as connection:
            for dataset_id, payload in rows.items():
                connection.execute(
                    meta.tables["datasets"].insert(),
                    {"id": dataset_id, "name": f"d{dataset_id}", "source": "csv", "rows": 1,
                     "rate_hz": 50.0, "duration_s": 1.0, "time_column": "time",
                     "channels": channels[dataset_id], "payload": payload,
                     "created_at": datetime(2026, 1, 2, tzinfo=UTC)},
                )  # fmt: skip
    finally:
        engine.dispose()


def _rows(url: str) -> dict[int, dict[str, Any]]:
    engine = make_engine(url)
    try:
        meta = MetaData()
        meta.reflect(engine, only=["datasets"])
        table = meta.tables["datasets"]
        with engine.connect() as connection:
            result = connection.execute(select(table).order_by(table.c.id)).mappings()
            return {row["id"]: dict(row) for row in result}
    finally:
        engine.dispose()


def _channels(signals: Signals) -> list[dict[str, Any]]:
    return [{"name": n, "unit": signals.units[n]} for n in signals.names]


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype == np.float64 and a.tobytes() == b.tobytes()


def _objects(store: ArtifactStore) -> list[str]:
    root = Path(store.root)
    return sorted(str(p.relative_to(root)) for p in root.rglob("*.parquet") if p.is_file())


def test_0008_moves_every_payload_to_the_store_and_the_downgrade_brings_them_back(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
    tmp_path: Path,
) -> None:
    url = fresh_url(backend)
    store_url = (tmp_path / "store").as_uri()
    store = open_store(store_url)
    upgrade(url, "0007")
    _insert(
        url,
        {i: pack_signals(s) for i, s in SAMPLES.items()},
        {i: _channels(s) for i, s in SAMPLES.items()},
    )

    upgrade(url, store_url=store_url)

    assert current_revision(url) == "0008"
    rows = _rows(url)
    assert sorted(rows) == sorted(SAMPLES)
    for dataset_id, signals in SAMPLES.items():
        row = rows[dataset_id]
        assert row["payload"] is None
        assert row["artifact"].startswith(f"datasets/{dataset_id}-")
        stored = Path(store.path(row["artifact"])).read_bytes()
        assert hashlib.sha256(stored).hexdigest() == row["content_sha256"]
        channels = [Channel(c["name"], c["unit"]) for c in row["channels"]]
        back = load_signals(
            store, StoredSamples(dataset_id, row["artifact"], row["content_sha256"]), channels
        )
        assert _same_bits(back.time, signals.time)
        for name in signals.names:
            assert _same_bits(back[name], signals[name]), (dataset_id, name)
    assert _objects(store) == sorted(r["artifact"] for r in rows.values())

    command.downgrade(alembic_config(url, store_url=store_url), "0007")

    assert current_revision(url) == "0007"
    rows = _rows(url)
    assert "artifact" not in next(iter(rows.values()))
    for dataset_id, signals in SAMPLES.items():
        arrays = blobs.unpack(rows[dataset_id]["payload"])
        assert _same_bits(arrays["time"], signals.time)
        for i, name in enumerate(signals.names):
            assert _same_bits(arrays[f"c{i}"], signals[name]), (dataset_id, name)

    upgrade(url, store_url=store_url)  # and forward again, from the blobs put back
    assert all(r["payload"] is None for r in _rows(url).values())


@pytest.mark.parametrize("bad", ["float32", "not-npz"])
def test_a_payload_that_cannot_move_losslessly_aborts_with_nothing_changed(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
    tmp_path: Path,
    bad: str,
) -> None:
    """Dataset 7's payload reads back differently (float32 stored as float64) or not at all:
    the migration stops naming it, every blob is intact, the schema is still 0007 and the
    store holds no object of the attempt."""
    url = fresh_url(backend)
    store_url = (tmp_path / "store").as_uri()
    upgrade(url, "0007")
    good = pack_signals(SAMPLES[2])
    wrong = (
        blobs.pack({"time": np.arange(4.0), "c0": np.arange(4, dtype=np.float32)})
        if bad == "float32"
        else b"not an npz"
    )
    _insert(url, {1: good, 7: wrong}, {1: _channels(SAMPLES[2]), 7: [{"name": "y", "unit": ""}]})
    before = _rows(url)

    with pytest.raises(Exception, match="dataset 7") as caught:
        upgrade(url, store_url=store_url)
    if bad == "float32":
        assert "did not read back bit for bit" in str(caught.value)

    assert current_revision(url) == "0007"
    assert _rows(url) == before
    engine = make_engine(url)
    try:
        columns = {c["name"] for c in inspect(engine).get_columns("datasets")}
    finally:
        engine.dispose()
    assert "artifact" not in columns
    assert _objects(open_store(store_url)) == []


def test_mapwise_db_upgrade_moves_the_payloads_to_the_configured_store(
    backend: str,
    fresh_url,  # type: ignore[no-untyped-def]
    tmp_path: Path,
) -> None:
    """The CLI takes the store from ``MAPWISE_STORE_URL`` (a relative path, resolved against
    its working directory); a payload that cannot move is one line on stderr, exit 2."""
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[3]
    env = os.environ | {"MAPWISE_STORE_URL": "moved-store", "PYTHONPATH": str(root)}

    def db_upgrade(url: str) -> subprocess.CompletedProcess[str]:
        command = [sys.executable, "-m", "app.cli", "db", "upgrade", "--database-url", url]
        return subprocess.run(
            command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
        )

    url = fresh_url(backend)
    upgrade(url, "0007")
    _insert(url, {3: pack_signals(SAMPLES[5])}, {3: _channels(SAMPLES[5])})
    done = db_upgrade(url)
    assert done.returncode == 0, done.stderr
    row = _rows(url)[3]
    assert row["payload"] is None
    assert (tmp_path / "moved-store" / row["artifact"]).is_file()

    broken = fresh_url(backend)
    upgrade(broken, "0007")
    _insert(broken, {4: b"not an npz"}, {4: [{"name": "y", "unit": ""}]})
    refused = db_upgrade(broken)
    assert refused.returncode == 2
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("mapwise: error: dataset 4: its samples cannot be moved")
    assert current_revision(broken) == "0007"
