"""A dataset stored as recorded, read a window at a time on a raster
(docs/data-formats.md#streamed-runs): every window of :class:`RasterRows` equals the same rows
of the whole read (:func:`load_on_raster`) bit for bit, on the default raster, a channel's and
a rate's (its last time past the span by a rounding too), with masked samples, held channels,
a gap that spans row groups and a channel logged only when it changes, without decoding the
groups across a gap; and it refuses a rate raster and a bad raster as the whole read does,
with the same message."""

from __future__ import annotations

import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest

from app.domain import Channel, StoredSamples
from app.io.errors import InputError
from app.io.ingest import ingest
from app.io.resample import Raster, Span, Track, parse_raster, span_of
from app.store import ArtifactStore, load_on_raster, open_store, save_staged, stage_recorded
from app.store.datasets import open_signals
from app.store.log_rows import open_rows
from app.store.parquet_signals import ROW_GROUP_ROWS
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


def test_a_rate_raster_whose_last_time_passes_the_span_by_a_rounding(tmp_path: Path) -> None:
    """``0 + 0.1·3`` is 0.30000000000000004, past the span's end at 0.3 s: the whole read
    holds the channel that ends there at its last value, and so does every window."""
    t1 = np.arange(31) * 0.01
    t1[-1] = 0.3
    t2 = np.linspace(0.0, 0.35, 351)
    tracks = [
        Track("a", "-", t1, np.sin(t1), False),
        Track("b", "-", t2, np.cos(t2), False),
    ]
    store, stored, channels = _stored(tmp_path, tracks)
    rows = _assert_windows_equal(store, stored, channels, ["a", "b"], parse_raster("100ms"))
    assert rows.time()[-1] > 0.3


def test_a_sparse_channel_never_makes_a_window_decode_the_log(tmp_path: Path) -> None:
    """A gear logged only when it changes (three samples in 20 row groups) and an
    interpolated channel masked over 14 of them: every window equals the whole read, and a
    one-row window in the middle holds a few row groups, not the groups across the gap
    (traced allocations, not time)."""
    n = 20 * ROW_GROUP_ROWS
    t = np.arange(n) * 0.001
    rpm = 2000.0 + 500.0 * np.sin(t)
    lam = 1.0 + 0.01 * np.cos(t / 3.0)
    lam[(t > 200.0) & (t < 1100.0)] = np.nan
    tracks = [
        Track("rpm", "rpm", t, rpm, False),
        Track("gear", "-", np.array([0.0, 1.0, t[-1]]), np.array([1.0, 2.0, 3.0]), True),
        Track("lambda", "-", t, lam, False),
    ]
    store, stored, channels = _stored(tmp_path, tracks)
    names = ["rpm", "gear", "lambda"]
    _assert_windows_equal(store, stored, channels, names, Raster(channel="rpm"))
    with open_rows(store, stored, channels, names, raster=Raster(channel="rpm")) as rows:
        assert isinstance(rows, RasterRows)
        middle = rows.n // 2
        tracemalloc.start()
        try:
            rows.rows(middle, middle + 1)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    group_bytes = ROW_GROUP_ROWS * (8 + 3 * 9)  # a decoded row group: time, values and presence
    assert peak < 8 * group_bytes, peak / group_bytes  # the gap spans 14 groups


def test_a_channel_raster_is_not_held_to_the_whole_tables_limits(tmp_path: Path) -> None:
    """A rate raster makes rows out of nothing and is refused over the limits, as the whole
    read refuses it; a channel's raster is its recorded samples, and a run never builds the
    table, so it is not (the whole read takes it too when the channels share timestamps)."""
    store, stored, channels = _stored(tmp_path, _tracks())
    names = ["fast", "mid"]
    spans = {c.name: Span(c.name, *c.timing) for c in channels if c.timing is not None}
    units = {c.name: c.unit for c in channels}
    with open_signals(store, stored.dataset_id, stored.key, stored.sha256) as file:
        on_fast = RasterRows(
            file, names, units, spans, Raster(channel="fast"), max_rows=1000, max_values=1000
        )
        assert on_fast.n > 1000
        with pytest.raises(InputError, match="limits are 1000 rows") as refused:
            RasterRows(file, names, units, spans, Raster(step=0.01), max_rows=1000, max_values=1000)
        assert refused.value.field == "raster"
