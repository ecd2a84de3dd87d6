"""The pyarrow CSV reader (:mod:`app.io.csv_files` + :mod:`app.io.csv_arrow`) against the
pure-Python reader it replaced (:mod:`tests.support.csv_reference`): on every CSV file and
CSV text of the test suite and on edge cases, both give identical values (bit for bit,
NaN where a sparse cell is empty), names, units, time column, delimiter and decimal mark —
or the same error message, field and line.

Each text is read with the default block size and with tiny blocks (a block boundary then
falls on nearly every line), through :func:`parse_csv` (``mapwise adapt``: non-numeric
columns dropped), with ``strict`` and through :func:`parse_sparse_csv` (the upload path).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import app.io.csv_arrow as csv_arrow
import app.io.csv_files as fast
import tests.support.csv_reference as reference
from app.io.errors import InputError
from app.io.export import series_to_csv
from tests.app.io.test_ingest_csv import BAD_FILES
from tests.support.helpers import log_csv

ROOT = Path(__file__).resolve().parents[3]
FILES = [
    ROOT / "app/data/example_nox.csv",
    *sorted((ROOT / "estimation/cycles/data").glob("*.csv")),
]


def _series() -> str:
    rng = np.random.default_rng(3)
    n = 3000
    t = np.arange(n) * 0.01
    channels = {f"c{i}": ("V", rng.normal(size=n) * 10.0 ** (i - 6)) for i in range(12)}
    return series_to_csv(t, channels)


def _sparse_export() -> str:
    """A sparse multi-rate export (pandas, as asammdf's ``to_dataframe``): empty cells."""
    import pandas as pd

    t = np.round(np.arange(400) * 0.005, 3)
    fast_ = np.sin(t * 7.0)
    slow = np.where(np.arange(400) % 4 == 0, np.cos(t), np.nan)
    mode = np.where(np.arange(400) % 10 == 0, np.arange(400) // 10 % 3, np.nan)
    frame = pd.DataFrame({"fast": fast_, "slow": slow, "mode": mode}, index=t)
    frame.index.name = "timestamps"
    return frame.to_csv(float_format="%.17g")


GOOD_TEXTS: dict[str, str] = {
    "log_csv helper": log_csv(500),
    "series_to_csv export": _series(),
    "sparse pandas export": _sparse_export(),
    "header units": "time [s],rpm [1/min],load [%]\n0,1000,10.5\n0.01,1010,-11\n0.02,1020,12\n",
    "units row, semicolon, decimal comma": (
        "time;rpm;temp\ns;1/min;°C\n0,0;1000,5;80\n0,5;1001,25;81\n"
    ),
    "tab, comments, BOM stripped": "# logger v2\nt\tx\n0\t1\n1\t2\n",
    "quoted fields": 'time,"a",b\n"0","1.5",2\n"1",  "2",3\n2,"3"4,5\n',
    "quoted field with the delimiter": 'time,a,note\n0,1,"x,y"\n1,2,"z"\n',
    "empty cells": "time,a,b\n0,1,\n1,,2\n2,3,4\n",
    "empty cells only in a text column": "time,a,b\n0,1,\n1,2,x\n",
    "written nan": "time,a\n0,1\n1,nan\n2,3\n",
    "written inf in the time column": "time,a\n0,1\ninf,2\n",
    "written nan(1) beside an inf": "time,a,b\n0,1,inf\n1,nan(1),2\n2,3,4\n",
    "written inf in a text column": "time,a,b\n0,1,inf\n1,2,x\n",
    "comments and blank lines in the body": (
        "time,a\n# c\n0,1\n\n   \n  # indented\n1,2\n\t\n2,3\n#end"
    ),
    "CRLF": "time,a,b\r\n0,1,2\r\n# c\r\n\r\n1,2,3\r\n",
    "lone CR": "time,a\r0,1\r# c\r\r1,2\r",
    "mixed line ends": "time,a\n0,1\r\n1,2\r2,3\n",
    "no final line end": "time,a\n0,1\n1,2",
    "padded numbers": "time,a\n 0 ,\t1\n1 , 2 \n",
    "plain number spellings": "time,a,b,c\n0,1.,+.5e-3,-2E+2\n1,.5,1e5,00012\n",
    "decimal comma with a decimal point cell": "time;a\n0,0;1,5\n0,5;2.5\n1,0;3\n",
    "decimal comma, tab": "time\tx\n0,0\t1,5\n0,5\t2,25\n",
    "text column": "time,mode,x\n0,idle,1\n1,run,2\n",
    "text column from a late row": "time,x,y\n"
    + "".join(f"{k},{k},{k}\n" for k in range(60))
    + "60,1,z\n",
    "no time column": "x,y\n1,2\n3,4\n5,6\n",
    "only a header": "time,x\n",
    "only units row": "time,x\ns,V\n",
    "unicode whitespace line": "time,a\n0,1\n\u00a0\n1,2\n",
    "non-ASCII comment": "time,a\n0,1\n# température\n1,2\n",
    "NA is text": "time,a\n0,1\n1,NA\n",
    "hex and underscore": "time,a,b\n0,0x10,1_0\n1,2,3\n",
    "nan(1)": "time,a\n0,1\n1,nan(1)\n",
    "huge exponent": "time,a\n0,1\n1,1e400\n",
    "tiny values": "time,a\n0,4.9e-324\n1,1e-400\n2,2.2250738585072014e-308\n",
    "decreasing time": "time,x\n0,1\n2,2\n1,3\n",
    "one column": "x\n1\n2\n3\n",
    "one column with a blank line of spaces": "x\n1\n  \n3\n",
    "one time column only": "time\n0\n1\n",
    "whitespace line in a 2-column file": "time,a\n0,1\n \n1,2\n",
    "quote spanning lines": 'time,a\n0,"1\n1,2"\n2,3\n',
    "row with a sample nowhere": "time,a,b\n0,1,2\n1,,\n2,3,4\n",
    "lone surrogate": "time,a\n0,1\n1,\ud800\n",
}
FILE_TEXTS = {path.name: path.read_text(encoding="utf-8-sig") for path in FILES}
BAD_TEXTS = {
    f"bad: {name}": content.decode("utf-8-sig", errors="replace")
    for name, content, *_ in BAD_FILES
    # the upload layer refuses these before parsing (binary data, the header limit)
    if b"\x00" not in content and name not in ("binary garbage", "huge header")
}
CORPUS = {**FILE_TEXTS, **GOOD_TEXTS, **BAD_TEXTS}


def _outcome(parse: Any, text: str, **kwargs: Any) -> dict[str, Any]:
    """What a reader makes of ``text``: its error (message, field, line) or its content."""
    try:
        log = parse(text, **kwargs)
    except InputError as exc:
        return {"error": (exc.message, exc.field, exc.line)}
    if hasattr(log, "signals"):
        s = log.signals
        columns = {name: s[name] for name in s.names}
        units = dict(s.units)
        return {
            "time": s.time,
            "columns": columns,
            "units": units,
            "meta": (log.time_column, log.delimiter, log.decimal),
        }
    return {
        "time": log.time,
        "columns": log.columns,
        "units": log.units,
        "meta": (log.time_column, log.decimal, log.empty),
        "masked": {name: rows.tolist() for name, rows in log.masked_rows.items()},
    }


def _same(new: dict[str, Any], old: dict[str, Any]) -> None:
    assert new.keys() == old.keys(), (new, old)
    if "error" in old:
        assert new["error"] == old["error"]
        return
    assert new["meta"] == old["meta"]
    assert new.get("masked") == old.get("masked")
    assert new["units"] == old["units"]
    assert list(new["columns"]) == list(old["columns"])
    for name in ["time", *old["columns"]]:
        a = new["time"] if name == "time" else new["columns"][name]
        b = old["time"] if name == "time" else old["columns"][name]
        assert a.dtype == b.dtype == np.float64, name
        np.testing.assert_array_equal(a, b, err_msg=name)  # bit for bit; NaN equals NaN
        assert np.array_equal(np.signbit(a), np.signbit(b)), name  # -0.0 stays -0.0


def _as_bytes(parse: Any) -> Any:
    """``parse`` given the UTF-8 bytes of the text (pure ASCII: parsed without decoding)."""
    return lambda text, **kwargs: parse(text.encode("utf-8", "surrogatepass"), **kwargs)


MODES = {
    "adapt": (fast.parse_csv, reference.parse_csv, {}),
    "strict": (fast.parse_csv, reference.parse_csv, {"strict": True}),
    "upload": (fast.parse_sparse_csv, reference.parse_sparse_csv, {}),
    "adapt, bytes": (_as_bytes(fast.parse_csv), reference.parse_csv, {}),
    "upload, bytes": (_as_bytes(fast.parse_sparse_csv), reference.parse_sparse_csv, {}),
}


@pytest.fixture(params=["default blocks", "tiny blocks"])
def block_chars(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> int:
    """The block size: the default, or 16 characters (a boundary after nearly every line;
    the repository's files, of thousands of lines, in blocks of 4096)."""
    if request.param == "tiny blocks":
        small = request.node.callspec.params.get("name") not in FILE_TEXTS
        monkeypatch.setattr(csv_arrow, "BLOCK_CHARS", 16 if small else 4096)
    return csv_arrow.BLOCK_CHARS


# Every case in every mode, except the bytes modes of a text that has no UTF-8 bytes.
CASES = [
    (name, mode)
    for name in CORPUS
    for mode in MODES
    if not ("bytes" in mode and name == "lone surrogate")
]


@pytest.mark.parametrize(("name", "mode"), CASES)
def test_same_values_or_error_as_the_python_reader(name: str, mode: str, block_chars: int) -> None:
    new_parse, old_parse, kwargs = MODES[mode]
    text = CORPUS[name]
    _same(_outcome(new_parse, text, **kwargs), _outcome(old_parse, text, **kwargs))


# Sparse exports with masked samples: the upload path only (``mapwise adapt`` drops a column
# with an empty cell, and refuses a non-finite value in one it keeps).
SPARSE_TEXTS = {
    "written nan and inf beside empty cells": (
        "time,a,b,c\n0,1,,inf\n0.5,,-inf,2\n1,NaN,3,\n1.5,4,Infinity,-INF\n2,5,6,7\n"
    ),
    "only masked samples on a row": "time,a,b\n0,1,2\n1,nan,inf\n2,3,\n",
    "masked samples over many blocks": "time,x,y\n"
    + "".join(f"{k},{'inf' if k % 7 == 3 else k},{'' if k % 2 else '-nan'}\n" for k in range(90)),
}


@pytest.mark.parametrize("mode", ["upload", "upload, bytes"])
@pytest.mark.parametrize("name", list(SPARSE_TEXTS))
def test_masked_samples_read_alike(name: str, mode: str, block_chars: int) -> None:
    """A written nan/inf in a sparse column is a masked sample: NaN, its row listed, on the
    pyarrow path as by the Python rules, whatever the block boundaries."""
    new_parse, old_parse, kwargs = MODES[mode]
    text = SPARSE_TEXTS[name]
    new = _outcome(new_parse, text, **kwargs)
    _same(new, _outcome(old_parse, text, **kwargs))
    assert "error" not in new
    assert new["masked"], new


@pytest.mark.parametrize("path", FILES, ids=[p.name for p in FILES])
def test_read_csv_of_the_repository_files(path: Path) -> None:
    """``read_csv`` on the CSV files in the repository (pure ASCII: read as bytes; with a
    BOM: decoded): the same log."""
    new, old = fast.read_csv(path), reference.read_csv(path)
    assert new.signals.names == old.signals.names
    assert new.time_column == old.time_column
    np.testing.assert_array_equal(new.signals.time, old.signals.time)
    for name in old.signals.names:
        np.testing.assert_array_equal(new.signals[name], old.signals[name])


def test_columns_requested_by_name() -> None:
    """``read_csv(columns=…)``: only those columns (the rest is never converted)."""
    text = "time,a,b,c\n0,1,x,3\n1,2,y,4\n"
    for columns in (["a"], ["c", "a"], ["b"]):
        new = _outcome(fast.parse_csv, text, columns=columns)
        _same(new, _outcome(reference.parse_csv, text, columns=columns))
    assert list(_outcome(fast.parse_csv, text, columns=["c", "a"])["columns"]) == ["a", "c"]


def test_a_log_over_many_blocks_keeps_lines_and_values(monkeypatch: pytest.MonkeyPatch) -> None:
    """A log cut into ~60 blocks: values are unchanged and an error deep inside names its
    line and column, as a decreasing time does through the Signals check."""
    monkeypatch.setattr(csv_arrow, "BLOCK_CHARS", 4096)
    rng = np.random.default_rng(1)
    n = 20_000
    values = rng.normal(size=(n, 3)) * [1.0, 1e-7, 1e9]
    rows = [f"{k * 0.01!r},{a!r},{b!r},{c!r}" for k, (a, b, c) in enumerate(values.tolist())]
    rows.insert(7000, "# a comment mid-file")
    text = "time [s],a [V],b [A],c [Pa]\n" + "\n".join(rows) + "\n"
    _same(_outcome(fast.parse_csv, text), _outcome(reference.parse_csv, text))
    broken = text.replace(f"\n{rows[15001]}\n", f"\n{rows[15001].replace(',', ',abc', 1)}\n")
    with pytest.raises(InputError) as info:
        fast.parse_sparse_csv(broken)
    line = 15001 + 2  # the header, then 1-based
    assert info.value.message.startswith(f"line {line}, column 'a': non-numeric value 'abc")
    decreasing = text.replace(
        f"\n{rows[12000]}\n", f"\n0.5{rows[12000][rows[12000].index(',') :]}\n"
    )
    new = _outcome(fast.parse_csv, decreasing)
    assert f"at line {12000 + 2}" in new["error"][0]
    _same(new, _outcome(reference.parse_csv, decreasing))


CELLS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(lambda v: f"{v:.6g}"),
    st.integers(-(10**20), 10**20).map(str),
    st.text(alphabet='0123456789.,+-eE _"#xnaifNAI \t', min_size=0, max_size=6),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    rows=st.lists(st.lists(CELLS, min_size=3, max_size=3), min_size=1, max_size=6),
    delimiter=st.sampled_from([",", ";", "\t"]),
    end=st.sampled_from(["\n", "\r\n"]),
)
def test_random_cells_read_alike(rows: list[list[str]], delimiter: str, end: str) -> None:
    """Arbitrary cells — numbers, near-numbers, quotes, comment marks — in every mode: the
    same values or the same error as the Python reader."""
    header = delimiter.join(["time", "a", "b"])
    body = [delimiter.join([str(k), *row[1:]]) for k, row in enumerate(rows)]
    text = end.join([header, *body]) + end
    for new_parse, old_parse, kwargs in MODES.values():
        _same(_outcome(new_parse, text, **kwargs), _outcome(old_parse, text, **kwargs))


def test_parsed_columns_are_plain_float64() -> None:
    """What the rest of mapwise gets: contiguous float64 numpy arrays."""
    log = fast.parse_csv(GOOD_TEXTS["series_to_csv export"])
    for name in log.signals.names:
        column = log.signals[name]
        assert column.dtype == np.float64
        assert column.flags.c_contiguous
        assert math.isfinite(float(column.sum()))


def test_read_csv_refuses_a_file_that_is_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin.csv"
    path.write_bytes("time,temp [°C]\n0,1\n1,2\n".encode("latin-1"))
    with pytest.raises(InputError) as info:
        fast.read_csv(path)
    assert info.value.message.startswith(f"{path}: not a UTF-8 text file (invalid")
    assert info.value.field == "file"
    with pytest.raises(InputError, match="no such file"):
        fast.read_csv(tmp_path / "none.csv")
