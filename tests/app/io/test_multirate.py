"""Measurement files as the tools write them (docs/data-formats.md#multi-rate): MDF4 and
MDF3 written by asammdf with a 1 kHz group among 10 ms and 100 ms groups, an enumeration,
a rational conversion with a pole, status and boolean channels, NaN/inf/invalid samples;
and the same data as asammdf's sparse CSV export. Held channels stay piecewise constant on
recorded values, the others equal ``np.interp`` over the valid samples, masked samples are
counted, and the raster is the one asked for (default: the slowest)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.io.errors import InputError
from app.io.ingest import IngestLimits, ParsedLog, ingest
from app.io.resample import Raster, Track, held_by_values, parse_raster, resample
from tests.support.measurements import (
    FAST,
    FLAG,
    LAMBDA_INVALID,
    MODE,
    NMOT,
    POLE,
    POLE_RAW,
    SPAN,
    SPEED,
    STATUS,
    T1,
    T10,
    T100,
    TEMP,
    Measurement,
    lambda_values,
    pole_physical,
    write_measurement,
    write_sparse_csv,
)

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

VERSIONS = ["4.10", "3.30"]
START, STOP = SPAN
INSIDE = (T1 >= START) & (T1 <= STOP)  # the 1 kHz samples within the common span
HELD = {"mode": (T10, MODE), "status": (T10, STATUS), "flag": (T10, FLAG.astype(float))}


@pytest.fixture(scope="module", params=VERSIONS)
def measurement(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    return write_measurement(tmp_path_factory.mktemp(f"mdf{request.param}"), request.param)


def held(time: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Zero-order hold, written independently of the code under test: the last recorded
    value at or before each grid time."""
    out = np.empty(grid.size)
    for k, t in enumerate(grid):
        out[k] = values[np.nonzero(time <= t)[0][-1]]
    return out


def continuous(name: str, measurement: Measurement) -> tuple[np.ndarray, np.ndarray]:
    """Timestamps and values of the valid samples of an interpolated channel."""
    if name == "fast":
        return T1, FAST
    if name == POLE:
        physical = pole_physical()
        ok = np.isfinite(physical)
        return T10[ok], physical[ok]
    if name == NMOT:
        return T100, SPEED
    if name == "tmot":
        return T100, TEMP.astype(float)
    values = lambda_values()
    ok = np.isfinite(values)
    if measurement.mdf4:
        ok[LAMBDA_INVALID] = False
    return T100[ok], values[ok]


def check_channels(ds: ParsedLog, measurement: Measurement) -> None:
    grid = ds.signals.time
    for name, (time, values) in HELD.items():
        if name not in ds.signals:
            continue
        got = ds.signals[name]
        np.testing.assert_array_equal(got, held(time, values, grid), err_msg=name)
        assert set(np.unique(got)) <= set(np.unique(values)), name
    for name in ("fast", POLE, NMOT, "tmot", "lambda"):
        if name not in ds.signals:
            continue
        time, values = continuous(name, measurement)
        np.testing.assert_allclose(
            ds.signals[name], np.interp(grid, time, values), rtol=1e-12, atol=1e-12, err_msg=name
        )


def test_default_raster_is_the_slowest_channel_within_the_common_span(
    measurement: Measurement,
) -> None:
    ds = ingest(measurement.bytes())
    np.testing.assert_array_equal(ds.signals.time, T100)  # the 100 ms group, all inside
    assert (ds.signals.time[0], ds.signals.time[-1]) == SPAN
    assert ds.signals.names == ["fast", "mode", POLE, "status", "flag", NMOT, "tmot", "lambda"]
    check_channels(ds, measurement)
    assert any(f"raster of channel {NMOT!r} (20 rows" in n for n in ds.notes), ds.notes


def test_masked_samples_are_counted_per_channel(measurement: Measurement) -> None:
    ds = ingest(measurement.bytes())
    poles = int(np.count_nonzero(POLE_RAW == 10))
    assert poles == 10
    lam = 3 if measurement.mdf4 else 2  # NaN, +inf and (MDF4 only) an invalid sample
    assert ds.masked == {POLE: poles, "lambda": lam}
    assert any(f"{POLE!r}: 10 of {T10.size} samples masked" in n for n in ds.notes)
    assert np.all(np.isfinite(ds.signals[POLE]))


@pytest.mark.parametrize("raster", ["100Hz", "10ms", "0.01 s", "0.1kHz"])
def test_a_rate_raster_is_a_uniform_grid(measurement: Measurement, raster: str) -> None:
    ds = ingest(measurement.bytes(), raster=raster)
    n = round((SPAN[1] - SPAN[0]) / 0.01) + 1
    np.testing.assert_allclose(ds.signals.time, SPAN[0] + 0.01 * np.arange(n), rtol=0, atol=1e-12)
    check_channels(ds, measurement)
    # held channels change value only at recorded switching instants
    mode = ds.signals["mode"]
    switches = ds.signals.time[1:][np.diff(mode) != 0]
    recorded = T10[1:][np.diff(MODE.astype(float)) != 0]
    for t in switches:
        assert np.any((recorded <= t) & (recorded > t - 0.01 - 1e-12)), t


def test_the_raster_of_a_named_channel(measurement: Measurement) -> None:
    ds = ingest(measurement.bytes(), raster="channel:fast")
    np.testing.assert_array_equal(ds.signals.time, T1[INSIDE])
    np.testing.assert_array_equal(ds.signals["fast"], FAST[INSIDE])
    check_channels(ds, measurement)


def test_kept_channels_set_the_default_raster_and_the_span(measurement: Measurement) -> None:
    ds = ingest(measurement.bytes(), channels=["fast", "mode", "flag"])
    assert ds.signals.names == ["fast", "mode", "flag"]
    np.testing.assert_array_equal(ds.signals.time, T10)  # 10 ms: the slowest kept
    np.testing.assert_array_equal(ds.signals["mode"], MODE)
    check_channels(ds, measurement)
    assert ds.masked == {}


def test_value_tables_keep_raw_values_and_note_the_table(measurement: Measurement) -> None:
    ds = ingest(measurement.bytes(), channels=["mode"])
    np.testing.assert_array_equal(ds.signals.time, T10)
    np.testing.assert_array_equal(ds.signals["mode"], MODE)
    assert any("'mode': raw values kept, value table 0=off, 1=idle, 2=run" in n for n in ds.notes)


def test_names_are_kept_as_recorded(measurement: Measurement) -> None:
    ds = ingest(measurement.bytes(), channels=[NMOT], units={NMOT: "rpm"})
    assert ds.channels == [{"name": "nmot_w\\ETK:1", "unit": "rpm"}]
    np.testing.assert_array_equal(ds.signals[NMOT], SPEED)


def test_bad_choices_name_the_field(measurement: Measurement) -> None:
    cases = [
        ({"channels": ["fast", "nope"]}, "channels", "'nope' not in the file"),
        ({"raster": "fast"}, "raster", "raster 'fast' is not understood"),
        ({"raster": "0Hz"}, "raster", "must be a positive rate"),
        ({"raster": "channel:nope"}, "raster", "raster channel 'nope' is not among"),
        ({"raster": "0.1us"}, "raster", "the 0.1 µs raster gives 190000"),  # default limits
    ]
    for kwargs, field, message in cases:
        with pytest.raises(InputError) as info:
            ingest(measurement.bytes(), **kwargs)  # type: ignore[arg-type]
        assert (info.value.field, info.value.status) == (field, 422), kwargs
        assert message in info.value.message, info.value.message


def test_a_rate_raster_is_bounded_before_it_is_allocated(measurement: Measurement) -> None:
    data = measurement.bytes()
    with pytest.raises(InputError, match=r"gives 19001 rows × 8 channels; the limits are 1000 "):
        ingest(data, raster="10kHz", limits=IngestLimits(max_rows=1000))
    with pytest.raises(InputError, match=r"gives 1901 rows × 8 channels; .* and 10000 values"):
        ingest(data, raster="1kHz", limits=IngestLimits(max_values=10_000))
    fits = IngestLimits(max_rows=1901, max_values=1901 * 8)
    assert ingest(data, raster="1kHz", limits=fits).rows == 1901


def test_a_channel_without_usable_samples_is_dropped(tmp_path: Path) -> None:
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    t = np.arange(50) * 0.01
    mdf.append([Signal(np.sin(t), t, name="ok"), Signal(np.full(50, np.inf), t, name="dead")])
    path = Path(mdf.save(tmp_path / "log.mf4", overwrite=True))
    mdf.close()
    ds = ingest(path)
    assert ds.signals.names == ["ok"]
    np.testing.assert_array_equal(ds.signals["ok"], np.sin(t))
    assert any("'dead' dropped: 0 usable samples of 50" in n for n in ds.notes), ds.notes
    with pytest.raises(InputError, match="no channel has usable samples") as info:
        ingest(path, channels=["dead"])
    assert info.value.field == "file"


def test_sparse_csv_export_reads_the_same_way(measurement: Measurement, tmp_path: Path) -> None:
    """asammdf's export without interpolation: each channel only on its own rows, its
    non-finite values written out."""
    kept = ["fast", "mode", "status", NMOT, "tmot"]
    path = write_sparse_csv(tmp_path, measurement, kept)
    text = path.read_text()
    assert ",," in text  # empty cells: the export is sparse
    ds = ingest(path)
    assert (ds.source, ds.time_column, ds.signals.names) == ("csv", "timestamps", kept)
    np.testing.assert_allclose(ds.signals.time, T100, rtol=0, atol=1e-15)
    check_channels(ds, measurement)
    assert any("column 'mode': a value on 200 of" in n for n in ds.notes), ds.notes
    assert any("held (previous value) ['mode', 'status']" in n for n in ds.notes), ds.notes
    rate = ingest(path, raster="channel:fast")
    np.testing.assert_allclose(rate.signals["fast"], FAST[INSIDE])

    # With the pole's channel (-inf at raw 10) and lambda (NaN, +inf and, in MDF4, an
    # invalid sample): a written -inf/inf is a masked sample counted per channel as from the
    # MDF, never a refusal; the exporter writes a NaN sample, and an invalid one, as an
    # empty cell (no sample), so lambda counts only its +inf.
    kept = ["fast", "mode", POLE, "status", NMOT, "tmot", "lambda"]
    (tmp_path / "all").mkdir()
    path = write_sparse_csv(tmp_path / "all", measurement, kept)
    text = path.read_text()
    assert text.count(",-inf,") == 10  # the pole, on its own rows
    ds = ingest(path)
    assert (ds.source, ds.time_column, ds.signals.names) == ("csv", "timestamps", kept)
    assert ds.masked == {POLE: 10, "lambda": 1}
    assert any(f"{POLE!r}: 10 of {T10.size} samples masked" in n for n in ds.notes), ds.notes
    assert np.all(np.isin(ds.signals.time, T100))  # a 100 ms raster, the slowest
    check_channels(ds, measurement)
    every = ingest(path, raster="10ms")
    assert every.masked == ds.masked
    check_channels(every, measurement)


def test_csv_rules_for_hold_and_for_empty_rows() -> None:
    assert held_by_values(np.array([0.0, 1.0, 2.0, np.nan, 1.0]))
    assert not held_by_values(np.arange(17.0))  # 17 distinct integers: a quantity
    assert not held_by_values(np.array([0.0, 0.5]))
    text = b"time,slow,fast\n0,1,10\n0.5,,11\n1,,12\n1.5,,13\n2,3,14\n"
    ds = ingest(text)
    np.testing.assert_array_equal(ds.signals.time, [0.0, 2.0])  # the slowest: 'slow'
    np.testing.assert_array_equal(ds.signals["fast"], [10.0, 14.0])
    fine = ingest(text, raster="2Hz")
    np.testing.assert_array_equal(fine.signals["slow"], [1, 1, 1, 1, 3])  # held: 2 levels
    np.testing.assert_array_equal(fine.signals["fast"], [10, 11, 12, 13, 14])
    with pytest.raises(InputError, match=r"line 3, column 'slow': empty value, and the row"):
        ingest(b"time,slow,fast\n0,1,10\n0.5,,\n1,2,12\n")
    masked = ingest(b"time,slow,fast\n0,1,10\n0.5,,inf\n1,2,12\n")  # written: masked
    assert masked.masked == {"fast": 1}
    np.testing.assert_array_equal(masked.signals["fast"], [10.0, 12.0])  # on 'slow': 0, 1 s
    with pytest.raises(InputError, match="no channel has usable samples") as info:
        ingest(b"time,slow,fast\n0,1,inf\n0.5,,nan\n1,2,-inf\n", channels=["fast"])
    assert info.value.field == "file"


def test_parse_raster_forms() -> None:
    assert parse_raster(None) == parse_raster(" ") == Raster()
    assert parse_raster("100Hz").step == pytest.approx(0.01)
    assert parse_raster("1 kHz").step == pytest.approx(0.001)
    assert parse_raster("250us").step == pytest.approx(250e-6)
    assert parse_raster("channel: nmot_w\\ETK:1") == Raster(channel="nmot_w\\ETK:1")
    for bad in ("100", "Hz", "-1ms", "1e999s", "channel:", "١٠٠Hz"):
        with pytest.raises(InputError):
            parse_raster(bad)


def test_resample_unchanged_when_nothing_is_to_do() -> None:
    t = np.arange(5.0)
    tracks = [Track("a", "", t, t * 2, False), Track("b", "", t, t + 0.5, True)]
    out = resample(tracks, Raster(), max_rows=10, max_values=10)
    assert out.time is t
    assert (out.notes, out.masked) == ([], {})
    np.testing.assert_array_equal(out.channels["b"], t + 0.5)
