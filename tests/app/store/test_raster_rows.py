"""A dataset stored as recorded, read a window at a time on a raster
(docs/data-formats.md#streamed-runs): every window of :class:`RasterRows` equals the same rows
of the whole read (:func:`load_on_raster`) bit for bit, on the default raster, a channel's and
a rate's, with masked samples, held channels and a gap that spans row groups; and it refuses
what the whole read refuses, with the same message."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from app.domain import Channel, StoredSamples
from app.io.errors import InputError
from app.io.ingest import ingest
from app.io.resample import Raster, Track, parse_raster, span_of
from app.store import ArtifactStore, load_on_raster, open_store, save_staged, stage_recorded
from app.store.log_rows import open_rows
from app.store.raster_rows import RasterRows
from tests.support.measurements import write_measurement

RNG_SEED = 20261206


def _tracks() -> list[Track]:
    """Four channels on their own timestamps over 240 s, about four row groups of the union:
    ``fast`` at about 1 kHz with jitter, ``mid`` at 10 ms with masked samples and a masked
    run of 70 s (longer than a row group), ``gear`` held at 20 ms, ``slow`` at 100 ms
    starting late."""
    rng = np.random.default_rng(RNG_SEED)
    fast_t = np.cumsum(rng.uniform(0.0009, 0.0011, 240_000))
    mid_t = np.arange(0.005, 240.0, 0.01)
    mid = np.sin(mid_t / 7.0) * 40.0 + 800.0
    mid[rng.choice(mid.size, 60, replace=False)] = np.nan
    mid[(mid_t > 100.0) & (mid_t < 170.0)] = np.nan
    gear_t = np.arange(0.0, 240.0, 0.02)
    slow_t = np.arange(3.05, 238.0, 0.1)
    return [
        Track("fast", "rpm", fast_t, 2000.0 + 500.0 * np.sin(fast_t), False),
        Track("mid", "hPa", mid_t, mid, False),
        Track("gear", "-", gear_t, np.floor(gear_t / 40.0) % 5, True),
        Track("slow", "degC", slow_t, 80.0 + np.cos(slow_t / 30.0), False),
    ]


def _stored(
    tmp_path: Path, tracks: list[Track]
) -> tuple[ArtifactStore, StoredSamples, list[Channel]]:
    store = open_store((tmp_path / "store").as_uri())
    with stage_recorded(store, tracks, {t.name: t.unit for t in tracks}) as staged:
        key = save_staged(store, 3, staged)
    # the spans ingest keeps on the dataset's row (app.services.datasets)
    channels = [Channel(t.name, t.unit, timing=_timing(t)) for t in tracks]
    return store, StoredSamples(3, key, staged.sha256), channels


def _timing(track: Track) -> tuple[float, float, float] | None:
    if np.count_nonzero(track.valid) < 2:
        return None
    span = span_of(track)
    return span.start, span.stop, span.step


def _windows(n: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """The whole log, its ends, single rows and random windows of every size."""
    picked = [(0, n), (0, 1), (n - 1, n), (0, 17), (n - 17, n)]
    for _ in range(40):
        a = int(rng.integers(0, n))
        picked.append((a, int(min(n, a + rng.integers(1, max(2, n // 3))))))
    return picked


def _assert_windows_equal(
    store: ArtifactStore,
    stored: StoredSamples,
    channels: list[Channel],
    names: list[str],
    raster: Raster | None,
) -> RasterRows:
    whole = load_on_raster(store, stored, channels, names, raster=raster)
    with open_rows(store, stored, channels, names, raster=raster) as rows:
        assert isinstance(rows, RasterRows)
        assert rows.n == len(whole.signals)
        assert rows.step_s == whole.step_s
        np.testing.assert_array_equal(rows.time(), whole.signals.time)
        assert rows.names == list(whole.signals.names)
        assert rows.units == dict(whole.signals.units)
        rng = np.random.default_rng(rows.n)
        for a, z in _windows(rows.n, rng):
            window = rows.rows(a, z)
            np.testing.assert_array_equal(window.time, whole.signals.time[a:z])
            for name in rows.names:
                # bit for bit, NaN nowhere: assert_array_equal would pass NaN == NaN
                assert np.array_equal(window[name], whole.signals[name][a:z]), (name, a, z)
        return rows


@pytest.mark.parametrize("raster", [None, "channel:fast", "channel:gear", "10ms", "3ms", "0.25s"])
def test_every_window_equals_the_whole_read(tmp_path: Path, raster: str | None) -> None:
    store, stored, channels = _stored(tmp_path, _tracks())
    assert stored is not None
    names = ["fast", "mid", "gear", "slow"]
    rows = _assert_windows_equal(
        store, stored, channels, names, None if raster is None else parse_raster(raster)
    )
    # the masked run of `mid` covers a whole row group: a window in it widens past it
    inside = (rows.first_times > 100.0) & (rows.last_times < 170.0)
    assert rows.groups >= 4
    assert inside.any()


def test_the_default_raster_is_the_slowest_read_channel(tmp_path: Path) -> None:
    store, stored, channels = _stored(tmp_path, _tracks())
    with open_rows(store, stored, channels, ["fast", "mid"]) as rows:
        assert isinstance(rows, RasterRows)
        assert rows.raster == Raster(channel="mid")
    with open_rows(store, stored, channels, ["fast", "mid", "slow"]) as rows:
        assert isinstance(rows, RasterRows)
        assert rows.raster == Raster(channel="slow")
    _assert_windows_equal(store, stored, channels, ["fast", "gear"], None)


def test_a_measurement_written_by_asammdf(tmp_path: Path) -> None:
    """The multi-rate MDF4 of the recorded-dataset tests (1 kHz, 10 ms and 100 ms groups,
    an enumeration, masked samples), through ingest."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        parsed = ingest(write_measurement(tmp_path).bytes())
    store, stored, channels = _stored(tmp_path, list(parsed.recorded))
    for raster in (None, Raster(step=0.004)):
        _assert_windows_equal(store, stored, channels, list(parsed.signals.names), raster)


@pytest.mark.parametrize(
    ("raster", "field"),
    [("channel:absent", "raster"), ("1us", "raster")],
)
def test_it_refuses_what_the_whole_read_refuses(tmp_path: Path, raster: str, field: str) -> None:
    store, stored, channels = _stored(tmp_path, _tracks())
    names = ["fast", "mid"]
    with pytest.raises(InputError) as whole:
        load_on_raster(store, stored, channels, names, raster=parse_raster(raster))
    with (
        pytest.raises(InputError) as streamed,
        open_rows(store, stored, channels, names, raster=parse_raster(raster)),
    ):
        pass
    assert str(streamed.value) == str(whole.value)
    assert streamed.value.field == whole.value.field == field


def test_a_channel_without_usable_samples_is_left_out(tmp_path: Path) -> None:
    tracks = _tracks()
    lone = np.full(tracks[3].time.size, np.nan)
    lone[5] = 1.0
    tracks.append(Track("lone", "-", tracks[3].time, lone, False))
    store, stored, channels = _stored(tmp_path, tracks)
    rows = _assert_windows_equal(store, stored, channels, ["fast", "lone", "slow"], None)
    assert "lone" not in rows.names
