"""Datasets stored as recorded (docs/data-formats.md#multi-rate): a multi-rate MDF4 written by
asammdf (1 kHz, 10 ms and 100 ms groups, an enumeration, a ±inf channel) uploaded without a
raster keeps each channel on its own timestamps, and each read puts the channels it needs on
the slowest raster among *them*: a read of 10 ms channels is on the 10 ms raster, one that
adds a 100 ms channel on the 100 ms raster, held channels stay piecewise constant on
recorded values. A whole-dataset read equals the upload's default resampling; an explicit
raster and a dense log are stored as before."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from app.domain import Channel, StoredSamples
from app.io.ingest import ParsedLog, ingest
from app.io.resample import Raster
from app.store import (
    ArtifactStore,
    load_on_raster,
    open_store,
    save_staged,
    stage_recorded,
    stage_signals,
)
from app.store.parquet_signals import SignalsFile
from tests.support.measurements import (
    MODE,
    NMOT,
    POLE,
    STATUS,
    T1,
    T10,
    T100,
    Measurement,
    pole_physical,
    write_measurement,
)

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

TEN_MS = ["mode", POLE, "status", "flag"]  # the 10 ms group
HELD = {"mode": MODE, "status": STATUS}


@pytest.fixture(scope="module")
def measurement(tmp_path_factory: pytest.TempPathFactory) -> Measurement:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return write_measurement(tmp_path_factory.mktemp("recorded"))


@pytest.fixture(scope="module")
def parsed(measurement: Measurement) -> ParsedLog:
    return ingest(measurement.bytes())


def _store(
    tmp_path: Path, parsed: ParsedLog, dataset_id: int = 7
) -> tuple[ArtifactStore, StoredSamples, list[Channel]]:
    store = open_store((tmp_path / "store").as_uri())
    with stage_recorded(store, parsed.recorded, dict(parsed.signals.units)) as staged:
        key = save_staged(store, dataset_id, staged)
    channels = [Channel(n, parsed.signals.units[n]) for n in parsed.signals.names]
    return store, StoredSamples(dataset_id, key, staged.sha256), channels


def held(time: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Zero-order hold written independently: the last recorded value at or before t."""
    return np.array([values[np.nonzero(time <= t)[0][-1]] for t in grid], dtype=np.float64)


def test_the_upload_keeps_the_channels_as_recorded(parsed: ParsedLog, tmp_path: Path) -> None:
    assert [t.name for t in parsed.recorded] == parsed.signals.names
    assert parsed.masked == {POLE: 10, "lambda": 3}  # still counted at upload
    assert "stored as recorded" in parsed.notes[-1]
    store, stored, _ = _store(tmp_path, parsed)
    with store.open(stored.key) as f:
        file = SignalsFile.open(f.read())
    union = np.unique(np.concatenate([T1, T10, T100]))
    assert file.recorded
    assert file.rows == union.size
    assert file.hold == {"mode", "status", "flag"}
    time, columns = file.read([NMOT, POLE])
    np.testing.assert_array_equal(time, union)
    by_name = {c.name: c for c in columns}
    np.testing.assert_array_equal(time[by_name[NMOT].present], T100)
    np.testing.assert_array_equal(time[by_name[POLE].present], T10)
    pole = by_name[POLE].values[by_name[POLE].present]
    physical = pole_physical()
    # a masked sample (±inf) is stored as NaN, a sample never recorded as null
    np.testing.assert_array_equal(np.isnan(pole), ~np.isfinite(physical))
    np.testing.assert_array_equal(pole[np.isfinite(physical)], physical[np.isfinite(physical)])
    # any Parquet reader sees the nulls
    table = pq.read_table(tmp_path / "store" / stored.key, columns=[NMOT])
    assert table.column(0).null_count == union.size - T100.size


def test_a_whole_dataset_read_is_the_uploads_default_raster(
    parsed: ParsedLog, tmp_path: Path
) -> None:
    store, stored, channels = _store(tmp_path, parsed)
    read = load_on_raster(store, stored, channels)
    assert read.raster == f"raster of channel {NMOT!r}"
    assert read.signals.names == parsed.signals.names
    np.testing.assert_array_equal(read.signals.time, parsed.signals.time)
    for name in parsed.signals.names:
        np.testing.assert_array_equal(read.signals[name], parsed.signals[name], err_msg=name)
        assert read.signals.units[name] == parsed.signals.units[name]


def test_ten_ms_channels_are_read_on_the_ten_ms_raster(parsed: ParsedLog, tmp_path: Path) -> None:
    store, stored, channels = _store(tmp_path, parsed)
    read = load_on_raster(store, stored, channels, TEN_MS)
    assert read.raster == "raster of channel 'mode'"
    assert read.step_s == pytest.approx(0.01)
    np.testing.assert_array_equal(read.signals.time, T10)  # every 10 ms sample, no span cut
    for name, values in HELD.items():
        got = read.signals[name]
        np.testing.assert_array_equal(got, values.astype(np.float64), err_msg=name)
    physical = pole_physical()
    ok = np.isfinite(physical)
    np.testing.assert_allclose(
        read.signals[POLE], np.interp(T10, T10[ok], physical[ok]), rtol=1e-12, atol=0
    )


def test_a_hundred_ms_channel_sets_the_raster_and_held_channels_stay_piecewise_constant(
    parsed: ParsedLog, tmp_path: Path
) -> None:
    store, stored, channels = _store(tmp_path, parsed)
    read = load_on_raster(store, stored, channels, ["mode", "status", NMOT])
    assert read.raster == f"raster of channel {NMOT!r}"
    assert read.step_s == pytest.approx(0.1)
    np.testing.assert_array_equal(read.signals.time, T100)
    for name, values in HELD.items():
        got = read.signals[name]
        np.testing.assert_array_equal(got, held(T10, values, T100), err_msg=name)
        assert set(np.unique(got)) <= set(np.unique(values.astype(np.float64))), name


def test_a_read_may_ask_for_its_own_raster(parsed: ParsedLog, tmp_path: Path) -> None:
    store, stored, channels = _store(tmp_path, parsed)
    read = load_on_raster(store, stored, channels, ["fast", "mode"], raster=Raster(step=0.05))
    assert read.raster == "50 ms raster"
    assert np.diff(read.signals.time) == pytest.approx(0.05)
    np.testing.assert_array_equal(read.signals["mode"], held(T10, MODE, read.signals.time))


def test_an_explicit_raster_and_a_dense_log_are_stored_as_before(
    measurement: Measurement, tmp_path: Path
) -> None:
    on_rate = ingest(measurement.bytes(), raster="10ms")
    assert on_rate.recorded == ()
    one_group = ingest(measurement.bytes(), channels=TEN_MS)  # one shared time base
    assert one_group.recorded == ()
    dense = "time,a,b\n" + "".join(f"{k * 0.1},{k},{k * k}\n" for k in range(50))
    assert ingest(dense.encode()).recorded == ()
    store = open_store((tmp_path / "store").as_uri())
    with stage_signals(store, one_group.signals) as staged:
        key = save_staged(store, 3, staged)
    with store.open(key) as f:
        assert not SignalsFile.open(f.read()).recorded
    stored = StoredSamples(3, key, staged.sha256)
    channels = [Channel(n, one_group.signals.units[n]) for n in one_group.signals.names]
    read = load_on_raster(store, stored, channels, ["mode"])
    assert (read.raster, read.step_s) == (None, None)
    np.testing.assert_array_equal(read.signals["mode"], one_group.signals["mode"])
