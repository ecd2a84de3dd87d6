"""MDF4 written with asammdf ingests equal (resampled where the groups' rates differ, a
non-finite sample masked), and broken or hostile MDF files get the right error. The
multi-rate rules in full: test_multirate.py."""

from __future__ import annotations

import io
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from asammdf import MDF, Signal

from app.io.errors import InputError
from app.io.ingest import IngestLimits, ingest

pytestmark = [
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    # asammdf's MDF4.__del__ trips over the half-built object of a file it refused; the
    # reader silences exactly that, so any unraisable exception left is a failure.
    pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning"),
]


def mdf_bytes(groups: list[list[Signal]], *, compression: int = 0, version: str = "4.10") -> bytes:
    mdf = MDF(version=version)
    for signals in groups:
        mdf.append(signals)
    buffer = io.BytesIO()
    mdf.save(buffer, compression=compression)
    mdf.close()
    return buffer.getvalue()


TIME = np.arange(0, 2.0, 0.01)
RNG = np.random.default_rng(0)
RPM = RNG.uniform(800, 4000, TIME.size)
LOAD = RNG.normal(0, 1e-3, TIME.size)


@pytest.mark.parametrize("compression", [0, 2])
def test_one_group_ingests_bit_exactly(compression: int) -> None:
    data = mdf_bytes(
        [[Signal(RPM, TIME, name="rpm", unit="1/min"), Signal(LOAD, TIME, name="load", unit="%")]],
        compression=compression,
    )
    ds = ingest(data)
    assert (ds.source, ds.time_column, ds.rows, ds.notes) == ("mdf4", "time", TIME.size, ())
    assert ds.channels == [{"name": "rpm", "unit": "1/min"}, {"name": "load", "unit": "%"}]
    np.testing.assert_array_equal(ds.signals.time, TIME)
    np.testing.assert_array_equal(ds.signals["rpm"], RPM)
    np.testing.assert_array_equal(ds.signals["load"], LOAD)
    assert ds.rate_hz == pytest.approx(100.0)


def test_integer_channels_become_float_and_text_is_skipped() -> None:
    t = np.arange(10) * 0.1
    gear = np.arange(10, dtype=np.uint8) % 6
    text = np.array([b"idle"] * 10)
    data = mdf_bytes(
        [[Signal(gear, t, name="gear"), Signal(text, t, name="state", encoding="latin-1")]]
    )
    ds = ingest(data)
    assert ds.signals.names == ["gear"]
    np.testing.assert_array_equal(ds.signals["gear"], gear.astype(float))
    assert any("'state' skipped" in n for n in ds.notes)


def test_groups_at_different_rates_go_onto_the_slowest_or_the_chosen_raster() -> None:
    """Default: the slowest group's timestamps (no more rows than the coarsest channel
    has); ``raster`` takes a rate instead. Both within the span all groups cover."""
    slow_t = np.arange(0.05, 1.96, 0.1)
    temp = 80 + slow_t**2
    data = mdf_bytes(
        [
            [Signal(RPM, TIME, name="rpm", unit="1/min")],
            [Signal(temp, slow_t, name="temp", unit="degC")],
        ]
    )
    ds = ingest(data)
    np.testing.assert_array_equal(ds.signals.time, slow_t)
    np.testing.assert_array_equal(ds.signals["temp"], temp)
    np.testing.assert_allclose(ds.signals["rpm"], np.interp(slow_t, TIME, RPM), rtol=1e-15)
    assert any("onto the raster of channel 'temp'" in n for n in ds.notes), ds.notes

    fast = ingest(data, raster="100Hz")
    grid = slow_t[0] + 0.01 * np.arange(191)
    np.testing.assert_allclose(fast.signals.time, grid, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.signals["rpm"], np.interp(grid, TIME, RPM), rtol=1e-12)
    np.testing.assert_allclose(fast.signals["temp"], np.interp(grid, slow_t, temp), rtol=1e-15)
    assert any("onto the 10 ms raster" in n for n in fast.notes), fast.notes


def test_a_non_finite_sample_is_masked_not_refused() -> None:
    nan = RPM.copy()
    nan[17] = np.nan
    ds = ingest(mdf_bytes([[Signal(nan, TIME, name="rpm"), Signal(LOAD, TIME, name="load")]]))
    assert ds.masked == {"rpm": 1}
    np.testing.assert_array_equal(ds.signals.time, TIME)
    np.testing.assert_array_equal(ds.signals["load"], LOAD)
    assert ds.signals["rpm"][17] == pytest.approx((RPM[16] + RPM[18]) / 2, rel=1e-12)
    np.testing.assert_array_equal(np.delete(ds.signals["rpm"], 17), np.delete(RPM, 17))
    assert any("'rpm': 1 of 200 samples masked" in n for n in ds.notes), ds.notes


def test_mdf3_reads_too(tmp_path) -> None:
    mdf = MDF(version="3.30")
    mdf.append([Signal(RPM, TIME, name="rpm", unit="1/min")])
    mdf.save(tmp_path / "log.mdf")
    mdf.close()
    ds = ingest(tmp_path / "log.mdf")
    np.testing.assert_array_equal(ds.signals["rpm"], RPM)


def patch_dz_original_size(data: bytes, size: int) -> bytes:
    start = data.index(b"##DZ")
    out = bytearray(data)
    struct.pack_into("<Q", out, start + 32, size)
    return bytes(out)


def bad_mdfs() -> list:
    good = mdf_bytes([[Signal(RPM, TIME, name="rpm")]])
    zipped = mdf_bytes(
        [[Signal(np.zeros(200_000), np.arange(200_000) * 0.01, name="z")]], compression=2
    )
    return [
        (
            "truncated",
            good[: len(good) // 2],
            "validation_error",
            "file",
            "the MDF file is truncated or corrupt (a block ends beyond the end of the",
        ),
        (
            "magic then garbage",
            b"MDF     4.10    " + bytes(200),
            "validation_error",
            "file",
            "the MDF file is truncated or corrupt (its identification or header block is not",
        ),
        (
            "unknown version",
            b"MDF     9.99    " + bytes(64),
            "unsupported_format",
            "file",
            "version '9.99'",
        ),
        (
            "no finite sample",
            mdf_bytes([[Signal(np.full(TIME.size, np.nan), TIME, name="rpm")]]),
            "validation_error",
            "file",
            "no channel has usable samples",
        ),
        (
            "duplicate time",
            mdf_bytes([[Signal(RPM[:3], np.array([0.0, 0.1, 0.1]), name="x")]]),
            "validation_error",
            "time",
            "channel group 0: time must be strictly increasing: duplicate time",
        ),
        (
            "only text",
            mdf_bytes([[Signal(np.array([b"a"] * 3), TIME[:3], name="s", encoding="latin-1")]]),
            "validation_error",
            "file",
            "no numeric channels",
        ),
        ("decompression bomb", zipped, "payload_too_large", "file", "inflate to more than"),
        (
            "lying zipped block",
            patch_dz_original_size(zipped, 1000),
            "validation_error",
            "file",
            "inflates to a different size",
        ),
    ]


@pytest.mark.parametrize(
    ("data", "code", "field", "message"), [pytest.param(*c[1:], id=c[0]) for c in bad_mdfs()]
)
def test_bad_mdf_corpus(data: bytes, code: str, field: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        ingest(data, limits=IngestLimits(max_decompressed_bytes=1_000_000))
    err = info.value
    assert (err.code, err.field) == (code, field), str(err)
    assert message in err.message


@pytest.mark.parametrize("version", ["4.10", "3.30"])
def test_truncated_or_corrupted_files_get_one_clear_message(version: str, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Cut a real file at every kind of place, or overwrite a stretch of it: always the same
    sentence, never asammdf's internals (a ``BytesIO`` repr, ``struct``'s buffer sizes)."""
    mdf = MDF(version=version)
    mdf.append([Signal(RPM, TIME, name="rpm", unit="1/min"), Signal(LOAD, TIME, name="load")])
    path = tmp_path / ("log.mf4" if version.startswith("4") else "log.mdf")
    mdf.save(path)
    mdf.close()
    good = path.read_bytes()
    cuts = [good[:n] for n in (16, 64, 65, 100, 300, len(good) // 3, len(good) // 2, len(good) - 8)]
    damaged = bytearray(good)
    damaged[64:200] = b"\xff" * 136
    for data in [*cuts, bytes(damaged)]:
        with pytest.raises(InputError) as info:
            ingest(data)
        message = info.value.message
        assert message.startswith("the MDF file is truncated or corrupt ("), message
        assert "BytesIO" not in message, message
        assert "unpack requires" not in message, message
        assert (info.value.field, info.value.status) == ("file", 422)


def test_refused_files_leave_no_traceback_on_stderr(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The server's log is its stderr: asammdf's ``__del__`` of a half-read file printed
    ``Exception ignored in: <function MDF4.__del__>`` and a traceback there."""
    good = mdf_bytes([[Signal(RPM, TIME, name="rpm")]])
    (tmp_path / "cut.mf4").write_bytes(good[: len(good) // 2])
    (tmp_path / "head.mf4").write_bytes(good[:100])
    script = (
        "import gc, sys\n"
        "from app.io.ingest import ingest\n"
        "for path in sys.argv[1:]:\n"
        "    try:\n"
        "        ingest(open(path, 'rb').read())\n"
        "    except ValueError as exc:\n"
        "        print(exc)\n"
        "gc.collect()\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "cut.mf4"), str(tmp_path / "head.mf4")],
        cwd=Path(__file__).resolve().parents[3],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert done.stdout.count("the MDF file is truncated or corrupt") == 2, done.stdout
    assert "Traceback" not in done.stderr, done.stderr
    assert "Exception ignored" not in done.stderr, done.stderr
