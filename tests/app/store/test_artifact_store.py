"""The artifact store on real filesystems (a ``file://`` directory and fsspec's ``memory://``):
datasets' samples round-trip bit for bit with their units, the hash catches a changed file,
a missing object is named, and the store's URL is resolved and checked at start-up."""

from __future__ import annotations

import hashlib
import secrets
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from pydantic import ValidationError

from app.config import Settings
from app.domain import Channel, StoredSamples
from app.store import (
    ArtifactCorruptError,
    ArtifactMissingError,
    ArtifactStore,
    delete_dataset,
    load_signals,
    open_store,
    resolve_store_url,
    save_staged,
    stage_signals,
)
from app.store.parquet_signals import ROW_GROUP_ROWS
from estimation.signals import Signals

N = 2 * ROW_GROUP_ROWS + 1234  # three row groups, the last one short


def _signals(n: int = N) -> Signals:
    rng = np.random.default_rng(7)
    channels = {
        "p_im.kPa": rng.normal(100.0, 5.0, n),
        "time": np.where(rng.random(n) < 0.5, -0.0, 0.0),  # a channel named like the time
        "tiny": rng.normal(0.0, 1e-300, n),
    }
    units = {"p_im.kPa": "kPa", "time": "s?", "tiny": ""}
    return Signals(np.cumsum(rng.uniform(0.001, 0.02, n)), channels, units)


def _channels(signals: Signals) -> list[Channel]:
    return [Channel(n, signals.units[n]) for n in signals.names]


def _bits(a: np.ndarray) -> bytes:
    assert a.dtype == np.float64
    return a.tobytes()


def _stores(tmp_path: Path) -> list[ArtifactStore]:
    return [
        open_store((tmp_path / "store").as_uri()),
        open_store(f"memory://mapwise-test-{secrets.token_hex(4)}"),
    ]


def test_samples_round_trip_bit_for_bit_on_a_directory_and_in_memory(tmp_path: Path) -> None:
    signals = _signals()
    for store in _stores(tmp_path):
        with stage_signals(store, signals) as staged:
            key = save_staged(store, 12, staged)
        assert key.startswith(f"datasets/12-{staged.sha256[:16]}-")
        assert key.endswith(".parquet")
        assert not staged.path.exists()  # the staged file was moved or removed
        data = store.read_bytes(key)
        assert hashlib.sha256(data).hexdigest() == staged.sha256
        back = load_signals(store, StoredSamples(12, key, staged.sha256), _channels(signals))
        assert back.names == signals.names
        assert _bits(back.time) == _bits(signals.time)
        for name in signals.names:
            assert _bits(back[name]) == _bits(signals[name]), name
        assert np.signbit(back["time"]).any()
        assert not np.signbit(back["time"]).all()


def test_the_file_is_plain_parquet_with_units_and_row_groups(tmp_path: Path) -> None:
    store = open_store((tmp_path / "store").as_uri())
    signals = _signals()
    with stage_signals(store, signals) as staged:
        key = save_staged(store, 1, staged)
    path = Path(store.path(key))
    assert path.is_file()
    assert path.is_relative_to(tmp_path / "store" / "datasets")
    reader = pq.ParquetFile(path)
    assert reader.metadata.num_row_groups == 3
    assert reader.metadata.num_rows == N
    schema = reader.schema_arrow
    assert schema.names == ["_time", "p_im.kPa", "time", "tiny"]
    units = [f.metadata[b"unit"].decode() for f in schema]
    assert units == ["s", "kPa", "s?", ""]
    assert all(f.type == pa.float64() and not f.nullable for f in schema)
    table = pq.read_table(path)  # any reader: here pyarrow's own
    assert _bits(table.column("p_im.kPa").to_numpy()) == _bits(signals["p_im.kPa"])
    assert sorted(p.name for p in (tmp_path / "store").rglob("*") if p.is_file()) == [path.name]


def test_a_changed_file_fails_its_hash_and_names_the_dataset_and_key(tmp_path: Path) -> None:
    for store in _stores(tmp_path):
        signals = _signals(500)
        with stage_signals(store, signals) as staged:
            key = save_staged(store, 4, staged)
        data = bytearray(store.read_bytes(key))
        data[len(data) // 2] ^= 0x01  # one bit, somewhere in the column chunks
        changed = store.path(key)
        with store.fs.open(changed, "wb") as f:
            f.write(bytes(data))
        with pytest.raises(ArtifactCorruptError) as caught:
            load_signals(store, StoredSamples(4, key, staged.sha256), _channels(signals))
        assert caught.value.status == 500
        assert caught.value.code == "artifact_corrupt"
        assert "dataset 4" in caught.value.message
        assert key in caught.value.message


def test_a_file_with_other_channels_is_refused(tmp_path: Path) -> None:
    store = open_store((tmp_path / "store").as_uri())
    signals = _signals(100)
    with stage_signals(store, signals) as staged:
        key = save_staged(store, 5, staged)
    with pytest.raises(ArtifactCorruptError, match="not the dataset's"):
        load_signals(store, StoredSamples(5, key, staged.sha256), [Channel("other", "")])


def test_a_missing_object_is_named(tmp_path: Path) -> None:
    for store in _stores(tmp_path):
        key = "datasets/9-0123456789abcdef-00000000.parquet"
        with pytest.raises(ArtifactMissingError) as caught:
            load_signals(store, StoredSamples(9, key, "0" * 64), [])
        assert caught.value.code == "artifact_missing"
        assert "dataset 9" in caught.value.message
        assert store.location(key) in caught.value.message


def test_a_failed_put_leaves_nothing_under_the_key(tmp_path: Path) -> None:
    for store in _stores(tmp_path):
        with pytest.raises(FileNotFoundError):
            store.put_file("datasets/1-x.parquet", tmp_path / "no-such-file")
        assert not store.exists("datasets/1-x.parquet")
        assert [p for p in store.fs.find(store.root) if "/datasets/" in p] == []


def test_deleting_removes_the_object_and_a_failed_delete_is_only_logged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    store = open_store((tmp_path / "store").as_uri())
    with stage_signals(store, _signals(10)) as staged:
        key = save_staged(store, 2, staged)
    assert delete_dataset(store, 2, key)
    assert not store.exists(key)
    assert delete_dataset(store, 2, key)  # already gone: nothing to do
    blocked = "datasets/3-blocked.parquet"
    Path(store.path(blocked)).mkdir(parents=True)  # a directory cannot be removed as a file
    (Path(store.path(blocked)) / "x").write_text("x")
    assert not delete_dataset(store, 3, blocked)
    assert "dataset 3 deleted, but its object" in caplog.text


def test_the_store_url_is_resolved_and_checked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MAPWISE_STORE_URL", raising=False)
    assert Settings().store_url == (tmp_path / "mapwise-data").as_uri()
    assert resolve_store_url("rel/dir") == (tmp_path / "rel" / "dir").as_uri()
    assert resolve_store_url("memory://bucket/x") == "memory://bucket/x"
    monkeypatch.setenv("MAPWISE_STORE_URL", "somewhere")
    assert Settings().store_url == (tmp_path / "somewhere").as_uri()
    assert open_store().url == (tmp_path / "somewhere").as_uri()
    with pytest.raises(ValidationError, match="unknown store URL scheme 'nosuch'"):
        Settings(store_url="nosuch://x")
