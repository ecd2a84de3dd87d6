"""Read drive logs from CSV into :class:`estimation.Signals` — the one CSV reader of mapwise.

Accepted layout: one header row (delimiter sniffed among ``, ; tab``); units either in the
header as ``name [unit]`` or in an optional second row whose non-empty cells are all
non-numeric; lines starting with ``#`` are comments. With ``;`` or tab as delimiter a decimal
comma (``1,5``) is recognised. Every problem is reported with its file line and column name.

The header, units row and delimiter are read in Python from the first lines
(:mod:`app.io.csv_sniff`); the body by :mod:`app.io.csv_arrow` with ``pyarrow.csv`` in
blocks, which falls back to the Python rules (:func:`app.io.csv_body.parse_body`) only for
a block pyarrow refuses or that holds a value mapwise refuses — so values and messages are
those of the Python rules alone (``tests/app/io/test_csv_equivalence.py`` holds the two to
that).

``mapwise adapt`` reads only the columns it needs (:func:`read_csv` with ``columns``); the
upload path (:mod:`app.io.ingest`) calls :func:`parse_sparse_csv`: every column must be
numeric, an empty cell is no sample of that channel (a sparse multi-rate export) and a
written ``nan``/``inf``/``-inf`` a masked sample of it, counted per channel, as in MDF
(`docs/data-formats.md#multi-rate`). ``mapwise adapt`` (:func:`read_csv`) has no raster to
fill a masked sample from: it refuses a non-finite value in a column it reads, naming the
line.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.io.csv_body import cell_columns
from app.io.csv_sniff import (
    TIME_COLUMNS,
    LogFormatError,
    check_delimiters,
    head_lines,
    is_units_row,
    sniff_decimal,
    sniff_delimiter,
    split_header,
    time_scale,
)
from app.io.names import bad_character, check_name
from estimation import Signals
from estimation.errors import SignalError

_NO_ROWS = np.empty(0, dtype=np.int64)


@dataclass(frozen=True, slots=True)
class CsvLog:
    """A loaded log and the column its time base came from (``None``: sample index)."""

    signals: Signals
    time_column: str | None
    delimiter: str = ","
    decimal: str = "."


@dataclass(frozen=True, slots=True)
class SparseCsv:
    """A CSV read with empty cells allowed: time (s, or the sample index), each column NaN
    where its cell is empty or holds a written non-finite value, units, the time column
    used, the empty cells per column and, per column that has any, the rows whose written
    ``nan``/``inf``/``-inf`` is a masked sample (a sample, unlike an empty cell)."""

    time: np.ndarray
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    time_column: str | None
    empty: dict[str, int]
    decimal: str = "."
    masked_rows: dict[str, np.ndarray] = field(default_factory=dict)

    def sampled(self, name: str) -> np.ndarray:
        """The rows holding a sample of ``name``: a value or a masked sample."""
        present = ~np.isnan(self.columns[name])
        rows = self.masked_rows.get(name)
        if rows is not None:
            present[rows] = True
        return present


@dataclass(frozen=True, slots=True)
class _Table:
    time: np.ndarray
    values: dict[str, np.ndarray | None]
    units: dict[str, str]
    time_column: str | None
    delimiter: str
    decimal: str
    rows: int
    line_of: Callable[[int], int]  # the file line of a data row, for messages
    masked: dict[str, np.ndarray]  # rows of the written non-finite values of sparse columns


def read_csv(
    path: str | Path,
    *,
    columns: Sequence[str] | None = None,
    time_column: str | None = None,
) -> CsvLog:
    """Load ``columns`` (default: every numeric column) of a CSV log.

    The time base is ``time_column`` (in its unit, s, ms, µs, ns, min or h, turned into
    seconds), else the first of :data:`TIME_COLUMNS` present, else the sample index (unit
    ``sample``, 1 Hz nominal).
    """
    path = Path(path)
    try:
        data = path.read_bytes()  # parsed as such when pure ASCII: no decoding, no copy
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such file", field="file") from None
    try:
        return parse_csv(data, columns=columns, time_column=time_column)
    except LogFormatError as exc:
        if exc.field == "file" and exc.line is None:
            raise LogFormatError(f"{path}: {exc}", field="file") from None
        raise


def parse_csv(
    text: str | bytes,
    *,
    columns: Sequence[str] | None = None,
    time_column: str | None = None,
    strict: bool = False,
    units: Mapping[str, str] | None = None,
    decimal: str | None = None,
    max_header_chars: int | None = None,
    max_columns: int | None = None,
) -> CsvLog:
    """Parse CSV ``text`` into a log.

    ``columns``: the channels wanted (each must be numeric); ``None`` keeps every numeric
    column, or — with ``strict`` — requires every column to be numeric. ``units`` overrides
    units by column name (an unknown name is an error, field ``units.<name>``). ``decimal``
    is ``"."``, ``","`` or ``None`` (detected). ``bytes`` are UTF-8 (a BOM is skipped);
    pure ASCII is parsed without decoding. Raises :class:`LogFormatError`.
    """
    text = _decoded(text)
    header = read_header(
        text,
        columns=columns,
        time_column=time_column,
        strict=strict,
        units=units,
        decimal=decimal,
        max_header_chars=max_header_chars,
        max_columns=max_columns,
        empty_is_missing=False,
    )
    table = _read_body(text, header)
    try:
        parsed = {name: v for name, v in table.values.items() if v is not None}
        signals = Signals(table.time, parsed, table.units, copy=False)
    except SignalError as exc:
        message, line = _with_line(str(exc), table.rows, table.line_of)
        raise LogFormatError(message, field=table.time_column or "time", line=line) from None
    return CsvLog(signals, table.time_column, table.delimiter, table.decimal)


def parse_sparse_csv(
    text: str | bytes,
    *,
    time_column: str | None = None,
    units: Mapping[str, str] | None = None,
    max_header_chars: int | None = None,
    max_columns: int | None = None,
) -> SparseCsv:
    """Parse CSV ``text`` whose channels may have empty cells: a sparse multi-rate export
    (MDA, asammdf ``to_dataframe(use_interpolation=False)``) holds each channel only on the
    rows of its own samples. Every column must be numeric (:func:`parse_csv` with
    ``strict``); an empty cell is no sample of that channel (NaN in
    :attr:`SparseCsv.columns`), except in the time column. A written ``nan``/``inf``/
    ``-inf`` is a masked sample (NaN, its row in :attr:`SparseCsv.masked_rows`), never a
    reason to refuse the file; in the time column it is refused. A row with no sample of
    any channel is refused, naming its line. ``bytes`` as in :func:`parse_csv`."""
    text = _decoded(text)
    header = read_header(
        text,
        columns=None,
        time_column=time_column,
        strict=True,
        units=units,
        decimal=None,
        max_header_chars=max_header_chars,
        max_columns=max_columns,
        empty_is_missing=True,
    )
    table = _read_body(text, header)
    try:
        Signals(table.time, {})
    except SignalError as exc:
        message, line = _with_line(str(exc), table.rows, table.line_of)
        raise LogFormatError(message, field=table.time_column or "time", line=line) from None
    values = {name: v for name, v in table.values.items() if v is not None}
    log = SparseCsv(
        table.time,
        values,
        {name: table.units[name] for name in values},
        table.time_column,
        {
            name: int(np.count_nonzero(np.isnan(v))) - table.masked.get(name, _NO_ROWS).size
            for name, v in values.items()
        },
        table.decimal,
        {name: rows for name, rows in table.masked.items() if name in values},
    )
    if values and table.time.size:
        sampled = np.zeros(table.time.size, dtype=bool)
        for name in values:
            sampled |= log.sampled(name)
        if not np.all(sampled):
            k = int(np.argmin(sampled))
            first, line = next(iter(values)), table.line_of(k)
            raise LogFormatError(
                f"line {line}, column {first!r}: empty value, and the row holds no "
                "sample of any channel",
                field=first,
                line=line,
            )
    return log


@dataclass(frozen=True, slots=True)
class CsvHeader:
    """What the first lines of a CSV say: the columns and their units (after overrides),
    the delimiter and decimal mark, the time column, the columns to read (name → strict),
    those where an empty cell is no sample, and where the body starts in the text."""

    names: list[str]
    units: dict[str, str]
    delimiter: str
    decimal: str
    time_column: str | None
    must: dict[str, bool]
    allowed_empty: frozenset[str]
    body_start: int
    time_scale: float = 1.0
    """Seconds per unit of the time column (1 for ``time [s]``, 1e-3 for ``time [ms]``)."""


def read_header(
    text: str | bytes,
    *,
    columns: Sequence[str] | None,
    time_column: str | None,
    strict: bool,
    units: Mapping[str, str] | None,
    decimal: str | None,
    max_header_chars: int | None,
    max_columns: int | None,
    empty_is_missing: bool,
) -> CsvHeader:
    """The header, units row, delimiter and decimal mark of CSV ``text`` (the rules of
    :func:`parse_csv`), read from its first 22 lines; with ``empty_is_missing`` an empty
    data cell will be no sample. ``text`` may be just the file's first lines."""
    head = head_lines(text, 22)  # header, units row and the 20 rows sniffed
    lines = [(n, ln) for n, ln, _ in head]
    if not lines:
        raise LogFormatError("empty file, expected a header row", field="file")
    header_line, header_text = lines[0]
    if max_header_chars is not None and len(header_text) > max_header_chars:
        raise LogFormatError(
            f"line {header_line}: header is {len(header_text)} characters long, "
            f"the limit is {max_header_chars}",
            field="header",
            line=header_line,
        )
    delimiter = sniff_delimiter([ln for _, ln in lines[:20]])
    rows = list(csv.reader([ln for _, ln in lines[:2]], delimiter=delimiter))
    numbers = [n for n, _ in lines]
    check_delimiters(lines[:20], delimiter, rows[0])
    names, header_units = split_header(rows[0], header_line)
    if max_columns is not None and len(names) > max_columns:
        raise LogFormatError(
            f"line {header_line}: {len(names)} columns, the limit is {max_columns}",
            field="header",
            line=header_line,
        )
    start = 1
    if len(rows) > 1 and is_units_row(rows[1]):
        if len(rows[1]) != len(names):
            raise LogFormatError(
                f"line {numbers[1]}: units row has {len(rows[1])} fields, header has {len(names)}",
                field="header",
                line=numbers[1],
            )
        header_units = [u.strip() or h for u, h in zip(rows[1], header_units, strict=True)]
        start = 2
    body_start = head[start - 1][2]
    sample = lines[start : start + 20]
    unit_of = dict(zip(names, header_units, strict=True))
    for name, unit in (units or {}).items():
        if name not in unit_of:
            raise LogFormatError(
                f"units given for unknown column {name!r}; the file has {names}",
                field=f"units.{name}",
            )
        unit_of[name] = str(unit)
    for name, unit in unit_of.items():  # the rule of names: no control or formatting character
        if bad_character(unit) is not None:
            check_name(unit, field=name, what=f"the unit of column {name!r},")
    if decimal is None:
        cells = cell_columns(
            [ln for _, ln in sample], [n for n, _ in sample], delimiter, len(names)
        )
        decimal = sniff_decimal([list(r) for r in zip(*cells, strict=True)], delimiter)
    if time_column is None:
        time_column = next((c for c in TIME_COLUMNS if c in names), None)
    elif time_column not in names:
        raise LogFormatError(
            f"time column {time_column!r} not in the file; columns: {names}", field=time_column
        )
    wanted = list(columns) if columns is not None else None
    if wanted is not None:
        missing = [c for c in wanted if c not in names]
        if missing:
            raise LogFormatError(
                f"missing column{'s' if len(missing) > 1 else ''} "
                f"{', '.join(repr(c) for c in missing)}; the file has {names}",
                field=missing[0],
            )
    must = {
        name: name == time_column or strict or wanted is not None
        for name in names
        if name == time_column or wanted is None or name in wanted
    }
    allowed_empty = {n for n in must if n != time_column} if empty_is_missing else set()
    scale = 1.0 if time_column is None else time_scale(time_column, unit_of[time_column])
    return CsvHeader(
        names,
        unit_of,
        delimiter,
        decimal,
        time_column,
        must,
        frozenset(allowed_empty),
        body_start,
        scale,
    )


def _decoded(text: str | bytes) -> str | bytes:
    """``text`` as it is parsed: pure-ASCII bytes as they are, other bytes as UTF-8 (a BOM
    skipped)."""
    if isinstance(text, bytes) and not text.isascii():
        try:
            return text.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise LogFormatError(f"not a UTF-8 text file ({exc.reason})", field="file") from None
    return text


def _read_body(text: str | bytes, header: CsvHeader) -> _Table:
    """The numeric columns of the body of CSV ``text`` after its ``header``."""
    from app.io.csv_arrow import read_body  # pyarrow: loaded with the first log read

    body = read_body(
        text,
        header.body_start,
        delimiter=header.delimiter,
        names=header.names,
        must=header.must,
        decimal=header.decimal,
        allowed_empty=header.allowed_empty,
    )
    values = body.values
    time_column = header.time_column
    stamps = values.pop(time_column) if time_column is not None else None
    if stamps is not None and header.time_scale != 1.0:
        stamps = stamps * header.time_scale
    time = stamps if stamps is not None else np.arange(body.rows, dtype=np.float64)
    return _Table(
        time,
        values,
        header.units,
        time_column,
        header.delimiter,
        header.decimal,
        body.rows,
        body.line_of,
        body.masked,
    )


def _with_line(message: str, rows: int, line_of: Callable[[int], int]) -> tuple[str, int | None]:
    """Rewrite ``at sample k`` in a Signals error as the file line."""
    match = re.search(r"at sample (\d+)", message)
    if match and int(match[1]) < rows:
        line = line_of(int(match[1]))
        return message.replace(match[0], f"at line {line}"), line
    return message, None


def write_csv(signals: Signals, path: str | Path, *, time_column: str = "time") -> None:
    """Write a log readable by :func:`read_csv`: header ``name [unit]``, time first, values
    with 17 significant digits (they round-trip exactly)."""
    names = signals.names
    if time_column in names:
        raise LogFormatError(f"a channel is already called {time_column!r}", field=time_column)
    header = [f"{time_column} [s]"] + [
        f"{n} [{signals.units[n]}]" if signals.units.get(n) else n for n in names
    ]
    columns = np.column_stack([signals.time, *(signals[n] for n in names)])
    with Path(path).open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(header)
        writer.writerows([[repr(float(v)) for v in row] for row in columns])
