"""Loading some of a dataset's channels (column projection): the chosen channels come back
bit for bit with their units, in the dataset's order, and the whole file's hash is still
checked, so a changed byte in a channel that is not read fails the load too."""

from __future__ import annotations

import secrets
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from app.domain import Channel, StoredSamples
from app.store import (
    ArtifactCorruptError,
    ArtifactStore,
    load_columns,
    load_signals,
    open_store,
    save_staged,
    stage_signals,
)
from app.store.parquet_signals import ROW_GROUP_ROWS
from estimation.signals import Signals

N = ROW_GROUP_ROWS + 777  # two row groups, the second short
NAMES = [f"c{i}" for i in range(8)]


def _signals() -> Signals:
    rng = np.random.default_rng(11)
    channels = {name: rng.normal(float(i), 1.0, N) for i, name in enumerate(NAMES)}
    units = {name: f"u{i}" for i, name in enumerate(NAMES)}
    return Signals(np.cumsum(rng.uniform(0.001, 0.02, N)), channels, units)


def _stored(store: ArtifactStore, signals: Signals, dataset_id: int) -> StoredSamples:
    with stage_signals(store, signals) as staged:
        key = save_staged(store, dataset_id, staged)
    return StoredSamples(dataset_id, key, staged.sha256)


def _channels(signals: Signals) -> list[Channel]:
    return [Channel(n, signals.units[n]) for n in signals.names]


def _stores(tmp_path: Path) -> list[ArtifactStore]:
    return [
        open_store((tmp_path / "store").as_uri()),
        open_store(f"memory://mapwise-test-{secrets.token_hex(4)}"),
    ]


def test_the_chosen_channels_come_back_bit_for_bit_in_the_datasets_order(
    tmp_path: Path,
) -> None:
    signals = _signals()
    for store in _stores(tmp_path):
        stored = _stored(store, signals, 21)
        chosen = {"c6", "c1", "c4", "not-a-channel"}  # an unknown name is left to the caller
        back = load_signals(store, stored, _channels(signals), chosen)
        assert back.names == ["c1", "c4", "c6"]
        assert back.units == {"c1": "u1", "c4": "u4", "c6": "u6"}
        assert back.time.tobytes() == signals.time.tobytes()
        for name in back.names:
            assert back[name].tobytes() == signals[name].tobytes(), name
        none = load_signals(store, stored, _channels(signals), [])
        assert none.names == []
        assert none.time.tobytes() == signals.time.tobytes()
        every = load_signals(store, stored, _channels(signals))
        assert every.names == NAMES


def test_a_changed_byte_in_a_channel_not_read_still_fails_the_hash(tmp_path: Path) -> None:
    store = open_store((tmp_path / "store").as_uri())
    signals = _signals()
    stored = _stored(store, signals, 22)
    path = Path(store.path(stored.key))
    chunk = pq.ParquetFile(path).metadata.row_group(1).column(NAMES.index("c7") + 1)
    data = bytearray(path.read_bytes())
    data[chunk.data_page_offset + chunk.total_compressed_size // 2] ^= 0x40
    path.write_bytes(bytes(data))
    with pytest.raises(ArtifactCorruptError, match="dataset 22") as caught:
        load_signals(store, stored, _channels(signals), ["c0"])
    assert "SHA-256" in caught.value.message


def test_a_projected_load_still_checks_the_files_channels(tmp_path: Path) -> None:
    store = open_store((tmp_path / "store").as_uri())
    signals = _signals()
    stored = _stored(store, signals, 23)
    time, columns = load_columns(store, 23, stored.key, stored.sha256, ["c2"])
    assert [(c.name, c.unit) for c in columns] == [("c2", "u2")]
    assert time.size == N
    other = Signals(signals.time[:10], {"c0": signals["c0"][:10]}, {"c0": "u0"})
    with pytest.raises(ArtifactCorruptError, match="not the dataset's"):
        load_signals(store, _stored(store, other, 24), _channels(signals), ["c0"])
