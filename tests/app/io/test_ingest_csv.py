"""CSV uploads through :func:`app.io.ingest.ingest`: good layouts parse, and every file of
the bad-file corpus gets its error code and the field at fault."""

from __future__ import annotations

import io

import numpy as np
import pytest

from app.io.errors import InputError
from app.io.ingest import IngestLimits, detect_format, ingest


def test_header_units_and_values() -> None:
    data = b"time [s],rpm [1/min],load [%]\n0,1000,10.5\n0.01,1010,-11\n0.02,1020,12\n"
    ds = ingest(data)
    assert ds.source == "csv"
    assert ds.time_column == "time"
    assert ds.rows == 3
    assert ds.channels == [{"name": "rpm", "unit": "1/min"}, {"name": "load", "unit": "%"}]
    assert ds.rate_hz == pytest.approx(100.0)
    assert ds.duration_s == pytest.approx(0.02)
    np.testing.assert_array_equal(ds.signals["load"], [10.5, -11.0, 12.0])


def test_units_row_semicolon_and_decimal_comma() -> None:
    data = "time;rpm;temp\ns;1/min;°C\n0,0;1000,5;80\n0,5;1001,25;81\n".encode()
    ds = ingest(data)
    assert ds.channels == [{"name": "rpm", "unit": "1/min"}, {"name": "temp", "unit": "°C"}]
    np.testing.assert_array_equal(ds.signals.time, [0.0, 0.5])
    np.testing.assert_array_equal(ds.signals["rpm"], [1000.5, 1001.25])
    assert "decimal comma" in ds.notes


def test_tab_delimiter_comments_bom_and_latin1() -> None:
    ds = ingest(b"\xef\xbb\xbf# logger v2\nt\tx\n0\t1\n1\t2\n")
    assert (ds.time_column, ds.signals.names) == ("t", ["x"])
    latin = "time,temp [°C]\n0,1\n1,2\n".encode("latin-1")
    ds = ingest(latin)
    assert ds.signals.units["temp"] == "°C"
    assert any("Latin-1" in n for n in ds.notes)


def test_units_sidecar_overrides_and_unknown_name_is_an_error() -> None:
    data = b"time,rpm,load\n0,1,2\n1,2,3\n"
    ds = ingest(data, units={"rpm": "1/min"})
    assert ds.signals.units == {"rpm": "1/min", "load": ""}
    with pytest.raises(InputError, match="unknown column 'speed'") as info:
        ingest(data, units={"speed": "1/min"})
    assert info.value.field == "units.speed"


@pytest.mark.parametrize(
    ("written", "scale"),
    [("ms", 1e-3), ("us", 1e-6), ("µs", 1e-6), ("ns", 1e-9), ("sec", 1.0), ("min", 60.0)],
)
def test_a_time_column_in_another_unit_is_read_as_seconds(written: str, scale: float) -> None:
    ticks = np.arange(50) * 10  # 10 units a row
    body = "".join(f"{t},{k}\n" for k, t in enumerate(ticks))
    in_header = ingest(f"time [{written}],x\n{body}".encode())
    in_units_row = ingest(f"time,x\n{written},-\n{body}".encode())
    in_form = ingest(f"time,x\n{body}".encode(), units={"time": written})
    for ds in (in_header, in_units_row, in_form):
        np.testing.assert_allclose(ds.signals.time, ticks * scale, rtol=1e-15)
        assert ds.duration_s == pytest.approx(490 * scale)
        assert ds.rate_hz == pytest.approx(1 / (10 * scale))


def test_a_time_column_in_a_unit_that_is_not_time_is_refused() -> None:
    with pytest.raises(InputError, match="'timestamp' is in 'rpm', not a unit of time") as info:
        ingest(b"timestamp [rpm],x\n0,1\n1,2\n")
    assert info.value.field == "timestamp"


def test_file_object_and_explicit_time_column() -> None:
    ds = ingest(io.BytesIO(b"stamp,x\n0,1\n2,3\n"), time_column="stamp")
    assert ds.time_column == "stamp"
    assert ds.rate_hz == pytest.approx(0.5)


def test_no_time_column_uses_the_sample_index() -> None:
    ds = ingest(b"x,y\n1,2\n3,4\n5,6\n")
    assert ds.time_column is None
    np.testing.assert_array_equal(ds.signals.time, [0.0, 1.0, 2.0])


HUGE_HEADER = "time," + ",".join(f"c{i}" for i in range(20000)) + "\n0," + "1," * 19999 + "1\n"

# (name, content, code, field, fragment of the message)
BAD_FILES = [
    (
        "text in numeric column",
        b"time,rpm,y\n0,1,2\n1,abc,3\n",
        "validation_error",
        "rpm",
        "line 3, column 'rpm': non-numeric value 'abc'",
    ),
    (
        "empty cell",
        b"time,rpm\n0,1\n1,\n",
        "validation_error",
        "rpm",
        "line 3, column 'rpm': empty",
    ),
    (
        "only masked samples",  # a written nan/inf is a masked sample: none is usable here
        b"time,rpm\n0,nan\n1,-inf\n2,1\n",
        "validation_error",
        "file",
        "no channel has usable samples",
    ),
    ("NaN in time", b"time,rpm\n0,1\nNaN,2\n", "validation_error", "time", "line 3, column 'time'"),
    (
        "duplicate timestamps",
        b"time,x\n0,1\n1,2\n1,3\n",
        "validation_error",
        "time",
        "duplicate time 1 s at line 4",
    ),
    (
        "decreasing time",
        b"time,x\n0,1\n2,2\n1,3\n",
        "validation_error",
        "time",
        "decreasing time 1 s at line 4",
    ),
    ("0 rows", b"time,x\n", "validation_error", "file", "no data rows"),
    ("0 rows after units", b"time,x\ns,V\n", "validation_error", "file", "no data rows"),
    ("one row", b"time,x\n0,1\n", "validation_error", "file", "too few samples: 1"),
    ("only time", b"time\n0\n1\n", "validation_error", "file", "no data channels"),
    ("empty file", b"", "validation_error", "file", "empty file"),
    ("blank file", b"\n\n  \n", "validation_error", "file", "empty file"),
    ("truncated row", b"time,x,y\n0,1,2\n1,2", "validation_error", "file", "line 3: 2 fields"),
    (
        "wrong delimiter",
        b"time|x|y\n0|1|2\n1|2|3\n",
        "validation_error",
        "file",
        "separated by '|'",
    ),
    (
        "space delimiter",
        b"time x y\n0 1 2\n1 2 3\n",
        "validation_error",
        "file",
        "separated by whitespace",
    ),
    (
        "duplicate column",
        b"time,x,x\n0,1,2\n1,2,3\n",
        "validation_error",
        "header",
        "duplicate column names ['x']",
    ),
    (
        "empty column name",
        b"time,,x\n0,1,2\n1,2,3\n",
        "validation_error",
        "header",
        "empty column name",
    ),
    ("huge header", HUGE_HEADER.encode(), "validation_error", "header", "the limit is 65536"),
    ("binary garbage", bytes(range(256)) * 8, "unsupported_format", "file", "binary data"),
    ("NUL inside text", b"time,x\n0,1\n1,\x002\n", "unsupported_format", "file", "binary data"),
    ("missing time column", b"x,y\n1,2\n3,4\n", "validation_error", "stamp", "time column 'stamp'"),
    # float() reads these as numbers; a log's cells are plain ASCII numbers only.
    (
        "digit separator",
        b"time,x\n0,1\n1,1_000\n",
        "validation_error",
        "x",
        "line 3, column 'x': '1_000' is not a plain number",
    ),
    (
        "Arabic-Indic digits",
        "time,x\n0,1\n1,\u0661\u0662\n".encode(),
        "validation_error",
        "x",
        "line 3, column 'x': '\u0661\u0662' is not a plain number",
    ),
    (
        "fullwidth digits",
        "time,x\n0,\uff11\n1,2\n".encode(),
        "validation_error",
        "x",
        "line 2, column 'x': '\uff11' is not a plain number",
    ),
    (
        "Devanagari digits in time",
        "time,x\n0,1\n\u0967,2\n".encode(),
        "validation_error",
        "time",
        "line 3, column 'time'",
    ),
    (
        "non-ASCII space",
        "time,x\n0,1\n1,\u00a02\n".encode(),
        "validation_error",
        "x",
        "line 3, column 'x'",
    ),
    (
        "digit separator after a chunk of good rows",
        ("time,x\n" + "".join(f"{k},{k}\n" for k in range(50)) + "50,2_5\n").encode(),
        "validation_error",
        "x",
        "line 52, column 'x': '2_5'",
    ),
    # one delimiter throughout, else the error says so and names the row
    (
        "mixed delimiters in every row",
        b"time,a;b\n0,1;2\n1,2;3\n",
        "validation_error",
        "header",
        "line 1: the delimiter is inconsistent: column 'time,a' contains ','",
    ),
    (
        "a row with another delimiter",
        b"time;a;b\n0;1;2\n1;2;3\n2,3,4\n",
        "validation_error",
        "file",
        "line 4: the delimiter is inconsistent: this row is separated by ','",
    ),
    (
        "rows with another delimiter than the header",
        b"time,a,b\n0;1;2\n1;2;3\n",
        "validation_error",
        "file",
        "line 2: the delimiter is inconsistent: this row is separated by ';'",
    ),
    (
        "a late row with another delimiter",
        (b"time;a\n" + b"".join(b"%d;%d\n" % (k, k) for k in range(40)) + b"40,1\n"),
        "validation_error",
        "file",
        "line 42: the delimiter is inconsistent",
    ),
    # names: control and format characters refused, naming the code point
    (
        "bidi override in a column name",
        "time,a\u202eb\n0,1\n1,2\n".encode(),
        "validation_error",
        "header",
        "U+202E (RIGHT-TO-LEFT OVERRIDE) at position 1",
    ),
    (
        "zero-width space in a column name",
        "time,\u200bx\n0,1\n1,2\n".encode(),
        "validation_error",
        "header",
        "U+200B (ZERO WIDTH SPACE) at position 0",
    ),
    (
        "C1 control in a column name",
        "time,x\u0085y\n0,1\n1,2\n".encode(),
        "validation_error",
        "header",
        "U+0085 at position 1",
    ),
]


@pytest.mark.parametrize(
    ("content", "code", "field", "message"),
    [pytest.param(*case[1:], id=case[0]) for case in BAD_FILES],
)
def test_bad_file_corpus(content: bytes, code: str, field: str, message: str) -> None:
    time_column = "stamp" if field == "stamp" else None
    with pytest.raises(InputError) as info:
        ingest(content, time_column=time_column)
    err = info.value
    assert (err.code, err.field) == (code, field), str(err)
    assert message in err.message
    assert err.status == {"validation_error": 422, "unsupported_format": 415}[code]
    assert "\n" not in err.message


def test_written_nan_and_inf_are_masked_samples_counted_per_channel() -> None:
    """A written ``nan``/``inf``/``-inf`` is a masked sample of its channel (filled from the
    valid neighbours, counted and noted per channel), never a refusal of the file; also
    with ``;`` and a decimal comma."""
    text = "time,rpm,temp\n0,1000.5,80.5\n1,nan,81.5\n2,1200.5,-inf\n3,1300.5,INF\n4,1400.5,84.5\n"
    for content in (text, text.replace(",", ";").replace(".", ",")):
        ds = ingest(content.encode())
        np.testing.assert_array_equal(ds.signals.time, [0, 1, 2, 3, 4])
        np.testing.assert_allclose(ds.signals["rpm"], [1000.5, 1100.5, 1200.5, 1300.5, 1400.5])
        np.testing.assert_allclose(ds.signals["temp"], [80.5, 81.5, 82.5, 83.5, 84.5])
        assert ds.masked == {"rpm": 1, "temp": 2}
        assert any("'temp': 2 of 5 samples masked" in n for n in ds.notes), ds.notes


def test_too_large_is_refused_before_parsing() -> None:
    body = b"time,x\n" + b"0,1\n" * 100
    with pytest.raises(InputError) as info:
        ingest(io.BytesIO(body), limits=IngestLimits(max_bytes=100))
    assert (info.value.code, info.value.field, info.value.status) == (
        "payload_too_large",
        "file",
        413,
    )
    assert "limit is 100 bytes" in str(info.value)


def test_path_source_size_checked_from_the_filesystem(tmp_path) -> None:
    path = tmp_path / "upload.bin"
    path.write_bytes(b"time,x\n0,1\n1,2\n")
    assert ingest(path).rows == 2
    with pytest.raises(InputError, match="limit is 5 bytes"):
        ingest(path, limits=IngestLimits(max_bytes=5))


def test_too_many_channels() -> None:
    data = b"time,a,b,c\n0,1,2,3\n1,2,3,4\n"
    with pytest.raises(InputError, match="4 columns, the limit is 3") as info:
        ingest(data, limits=IngestLimits(max_channels=2))
    assert info.value.field == "header"


def test_format_comes_from_magic_bytes_not_the_name() -> None:
    assert detect_format(b"\x89MCAP0\r\nrest") == "mcap"
    assert detect_format(b"MDF     4.10    ") == "mdf4"
    assert detect_format(b"time,x\n") == "csv"
    with pytest.raises(InputError) as info:
        detect_format(b"PK\x03\x04\x14\x00\x00\x00")  # a zip file
    assert info.value.code == "unsupported_format"


def test_large_log_parses_exactly() -> None:
    """100 000 rows × 12 channels round-trip bit-exactly."""
    from app.io.export import series_to_csv

    rng = np.random.default_rng(0)
    n = 100_000
    t = np.arange(n) * 0.01
    channels = {f"c{i}": ("V", rng.normal(size=n) * 10 ** (i - 6)) for i in range(12)}
    text = series_to_csv(t, channels).encode()
    ds = ingest(text)  # its speed: scripts/bench_service.py (a 360 000-row upload)
    assert ds.rows == n
    np.testing.assert_array_equal(ds.signals.time, t)
    for name, (_, values) in channels.items():
        np.testing.assert_array_equal(ds.signals[name], values)


def test_spooled_upload_file_is_read_from_its_position() -> None:
    import tempfile

    with tempfile.SpooledTemporaryFile(max_size=16) as spooled:  # rolls over to disk
        spooled.write(b"time,x\n0,1\n1,2\n2,4\n")
        spooled.seek(0)
        ds = ingest(spooled)
    np.testing.assert_array_equal(ds.signals["x"], [1.0, 2.0, 4.0])


def test_logs_longer_than_a_chunk_keep_line_numbers_and_column_rules() -> None:
    """Logs are converted CHUNK_ROWS rows at a time: an error in a later chunk still names its
    file line, and a column that turns non-numeric only there is still dropped (non-strict)
    or refused (upload)."""
    from app.io.csv_body import CHUNK_ROWS
    from app.io.csv_files import parse_csv

    n = 2 * CHUNK_ROWS + 7
    rows = [f"{k * 0.01:.2f},{k},{k % 5}" for k in range(n)]
    bad = CHUNK_ROWS + 123  # body index; file line = index + 3 (header, comment, 1-based)
    rows[bad] = f"{bad * 0.01:.2f},{bad},oops"
    text = "time [s],a [-],b [-]\n# a comment\n" + "\n".join(rows) + "\n"
    log = parse_csv(text)
    assert log.signals.names == ["a"]
    np.testing.assert_array_equal(log.signals["a"], np.arange(n, dtype=float))
    with pytest.raises(InputError) as info:
        ingest(text.encode())
    assert info.value.field == "b"
    assert f"line {bad + 3}, column 'b': non-numeric value 'oops'" in info.value.message


def test_plain_number_spellings_and_names_kept_as_given() -> None:
    """What the strict syntax still takes, and names that are text however odd: kept."""
    content = (
        "time,p/q [bar],C:\\x,\u00e9t\u00e9 \U0001f697,\u05e9\u05dd\n"
        " 0 ,1.,+.5e-3,-2E+2,7\n"
        "1,2,3,4,8\n"
    ).encode()
    ds = ingest(content)
    assert ds.signals.names == ["p/q", "C:\\x", "\u00e9t\u00e9 \U0001f697", "\u05e9\u05dd"]
    assert ds.signals.units["p/q"] == "bar"
    np.testing.assert_array_equal(ds.signals["p/q"], [1.0, 2.0])
    np.testing.assert_array_equal(ds.signals["C:\\x"], [5e-4, 3.0])
    np.testing.assert_array_equal(ds.signals["\u00e9t\u00e9 \U0001f697"], [-200.0, 4.0])


def test_adapt_drops_a_column_that_is_not_plain_numbers() -> None:
    """``mapwise adapt`` keeps only numeric columns: ``1_000`` makes a column non-numeric
    there too, instead of silently 1000."""
    from app.io.csv_files import parse_csv

    log = parse_csv("time,a,b\n0,1,1_000\n1,2,2\n")
    assert log.signals.names == ["a"]
    with pytest.raises(InputError, match="'1_000' is not a plain number"):
        parse_csv("time,a,b\n0,1,1_000\n1,2,2\n", columns=["b"])


@pytest.mark.parametrize(
    ("data", "units"),
    [
        ("time,a [r\u202epm]\n0,1\n1,2\n".encode(), None),  # a right-to-left override
        (b"time,a\n0,1\n1,2\n", {"a": "r\x00pm"}),  # a NUL, from the units field
        ("time,a\ns,r\u200bpm\n0,1\n1,2\n".encode(), None),  # a zero-width space, units row
    ],
)
def test_a_unit_with_a_control_or_formatting_character_is_refused(
    data: bytes, units: dict[str, str] | None
) -> None:
    with pytest.raises(InputError, match="the unit of column 'a'") as info:
        ingest(data, units=units)
    assert info.value.field == "a"


def test_a_second_column_named_like_a_time_base_is_kept_and_noted() -> None:
    ds = ingest(b"time_s,t,x\n0,5,1\n0.5,6,2\n1,7,3\n")
    assert ds.time_column == "time_s"
    assert ds.signals.names == ["t", "x"]
    assert "time from 'time_s'; 't' also named like a time base, kept as a channel" in ds.notes
    assert not any("time base" in n for n in ingest(b"time,x\n0,1\n1,2\n").notes)
