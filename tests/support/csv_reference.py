"""The pure-Python CSV reader of mapwise before pyarrow (``app/io/csv_files.py`` at commit
4cfd555), kept as the slow reference: tests check that
:mod:`app.io.csv_files` gives the same values and messages, and ``scripts/bench_ingest.py``
times it. Not used by the application.

One rule has changed since (issue 16): in :func:`parse_sparse_csv` (the upload path) a
written ``nan``/``inf``/``-inf`` is a masked sample, NaN with its row in
``SparseCsv.masked_rows``, no longer a refusal. Its rules, otherwise as they were: one
header row (delimiter sniffed among ``, ; tab``); units either in the header as ``name
[unit]`` or in an optional second row whose non-empty cells are all non-numeric; lines
starting with ``#`` are comments. With ``;`` or tab as delimiter a decimal comma (``1,5``)
is recognised. Every problem is reported with its file line and column name.
"""

from __future__ import annotations

import csv
import re
from collections import Counter
from collections.abc import Mapping, Sequence, Set
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.io.errors import InputError
from app.io.names import check_name
from estimation import Signals
from estimation.errors import SignalError

TIME_COLUMNS = ("time", "time_s", "t", "timestamp", "timestamps")  # the last: asammdf's exports
DELIMITERS = ",;\t"
_HEADER_UNIT = re.compile(r"^\s*(?P<name>.+?)\s*\[(?P<unit>[^\]]*)\]\s*$")
_DECIMAL_COMMA = re.compile(r"^\s*[+-]?\d+,\d+([eE][+-]?\d+)?\s*$")
_DECIMAL_POINT = re.compile(r"\d\.\d")
# The one number syntax of a cell: plain ASCII digits, sign, point, exponent (and the NaN/inf
# spellings, which the finite check then refuses with its own message). float() alone would
# also take ``1_000``, Arabic-Indic or fullwidth digits and non-ASCII spaces.
_NUMBER = re.compile(
    r"\s*[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|nan|inf|infinity)\s*",
    re.IGNORECASE | re.ASCII,
)
CHUNK_ROWS = 20_000


class LogFormatError(InputError, SignalError):
    """The file is not a usable log; the message names the line and column."""


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
    where its cell is empty, units, the time column used and the empty cells per column."""

    time: np.ndarray
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    time_column: str | None
    empty: dict[str, int]
    decimal: str = "."
    masked_rows: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class _Table:
    time: np.ndarray
    values: dict[str, np.ndarray | None]
    units: dict[str, str]
    time_column: str | None
    delimiter: str
    decimal: str
    lines: list[int]
    masked: dict[str, np.ndarray] = field(default_factory=dict)


def read_csv(
    path: str | Path,
    *,
    columns: Sequence[str] | None = None,
    time_column: str | None = None,
) -> CsvLog:
    """Load ``columns`` (default: every numeric column) of a CSV log.

    The time base is ``time_column`` (seconds), else the first of :data:`TIME_COLUMNS`
    present, else the sample index (unit ``sample``, 1 Hz nominal).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such file", field="file") from None
    except UnicodeDecodeError as exc:
        raise LogFormatError(
            f"{path}: not a UTF-8 text file ({exc.reason})", field="file"
        ) from None
    try:
        return parse_csv(text, columns=columns, time_column=time_column)
    except LogFormatError as exc:
        if exc.field == "file" and exc.line is None:
            raise LogFormatError(f"{path}: {exc}", field="file") from None
        raise


def parse_csv(
    text: str,
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
    is ``"."``, ``","`` or ``None`` (detected). Raises :class:`LogFormatError`.
    """
    table = _read_table(
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
    try:
        parsed = {name: v for name, v in table.values.items() if v is not None}
        signals = Signals(table.time, parsed, table.units)
    except SignalError as exc:
        message, line = _with_line(str(exc), table.lines)
        raise LogFormatError(message, field=table.time_column or "time", line=line) from None
    return CsvLog(signals, table.time_column, table.delimiter, table.decimal)


def parse_sparse_csv(
    text: str,
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
    :attr:`SparseCsv.columns`), except in the time column. A written ``nan``/``inf`` is a
    masked sample (NaN, its row in ``masked_rows``). A row with no sample of any channel is
    refused, naming its line."""
    table = _read_table(
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
    try:
        Signals(table.time, {})
    except SignalError as exc:
        message, line = _with_line(str(exc), table.lines)
        raise LogFormatError(message, field=table.time_column or "time", line=line) from None
    values = {name: v for name, v in table.values.items() if v is not None}
    if values and table.time.size:
        sampled = np.zeros(table.time.size, dtype=bool)
        for name, v in values.items():
            sampled |= np.isfinite(v)
            sampled[table.masked.get(name, [])] = True
        if not np.all(sampled):
            k = int(np.argmin(sampled))
            first = next(iter(values))
            raise LogFormatError(
                f"line {table.lines[k]}, column {first!r}: empty value, and the row holds no "
                "sample of any channel",
                field=first,
                line=table.lines[k],
            )
    return SparseCsv(
        table.time,
        values,
        {name: table.units[name] for name in values},
        table.time_column,
        {
            name: int(np.count_nonzero(np.isnan(v))) - len(table.masked.get(name, []))
            for name, v in values.items()
        },
        table.decimal,
        {name: rows for name, rows in table.masked.items() if name in values},
    )


def _read_table(
    text: str,
    *,
    columns: Sequence[str] | None,
    time_column: str | None,
    strict: bool,
    units: Mapping[str, str] | None,
    decimal: str | None,
    max_header_chars: int | None,
    max_columns: int | None,
    empty_is_missing: bool,
) -> _Table:
    """The header, units and numeric columns of CSV ``text`` (the rules of
    :func:`parse_csv`); with ``empty_is_missing`` an empty data cell is NaN."""
    lines = _content_lines(text)
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
    _check_delimiters(lines[:20], delimiter, rows[0])
    names, header_units = _split_header(rows[0], header_line)
    if max_columns is not None and len(names) > max_columns:
        raise LogFormatError(
            f"line {header_line}: {len(names)} columns, the limit is {max_columns}",
            field="header",
            line=header_line,
        )
    start = 1
    if len(rows) > 1 and _is_units_row(rows[1]):
        if len(rows[1]) != len(names):
            raise LogFormatError(
                f"line {numbers[1]}: units row has {len(rows[1])} fields, header has {len(names)}",
                field="header",
                line=numbers[1],
            )
        header_units = [u.strip() or h for u, h in zip(rows[1], header_units, strict=True)]
        start = 2
    body = [ln for _, ln in lines[start:]]
    lines_of_body = numbers[start:]
    del lines  # the body and its line numbers are all that is needed from here on
    unit_of = dict(zip(names, header_units, strict=True))
    for name, unit in (units or {}).items():
        if name not in unit_of:
            raise LogFormatError(
                f"units given for unknown column {name!r}; the file has {names}",
                field=f"units.{name}",
            )
        unit_of[name] = str(unit)
    if decimal is None:
        head = _columns(body[:20], lines_of_body[:20], delimiter, len(names))
        decimal = sniff_decimal([list(r) for r in zip(*head, strict=True)], delimiter)
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
    masked: dict[str, list[int]] = {}
    values = _parse_body(
        body, lines_of_body, delimiter, names, must, decimal, allowed_empty, masked
    )
    stamps = values.pop(time_column) if time_column is not None else None
    time = stamps if stamps is not None else np.arange(len(lines_of_body), dtype=np.float64)
    masked_rows = {n: np.array(rows, dtype=np.int64) for n, rows in masked.items()}
    return _Table(
        time, values, unit_of, time_column, delimiter, decimal, lines_of_body, masked_rows
    )


def split_lines(text: str) -> list[str]:
    """Lines ended by LF, CRLF or CR only: :meth:`str.splitlines` also breaks at U+0085,
    U+2028 and U+2029, which may sit inside a cell (and must then be judged there)."""
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def _content_lines(text: str) -> list[tuple[int, str]]:
    """Non-blank, non-comment lines with their 1-based line numbers."""
    return [
        (n, ln)
        for n, ln in enumerate(split_lines(text), start=1)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]


def sniff_delimiter(sample_lines: list[str]) -> str:
    """The column delimiter among tab, ``;`` and ``,``.

    First choice: a delimiter that occurs equally often (and at least once) on every sample
    line, preferring tab, then ``;`` (whose files often use a decimal comma, so ``,`` may be
    just as regular), then ``,``; else :class:`csv.Sniffer` (quoted fields); else the one
    most frequent in the header.
    """
    for d in ("\t", ";", ","):
        counts = {line.count(d) for line in sample_lines}
        if len(counts) == 1 and 0 not in counts:
            return d
    try:
        return csv.Sniffer().sniff("\n".join(sample_lines), delimiters=DELIMITERS).delimiter
    except csv.Error:
        header = sample_lines[0]
        counts = {d: header.count(d) for d in DELIMITERS}
        best = max(counts, key=lambda d: counts[d])
        return best if counts[best] else ","


def _check_delimiters(sample: list[tuple[int, str]], delimiter: str, header: list[str]) -> None:
    """Refuse a file whose lines are split by different delimiters, naming the line.

    Two signatures: a row that has the header's field count only when split at another
    delimiter; and a header cell holding another delimiter that recurs in exactly the same
    columns of every sampled row (``time,a;b`` over ``0,1;2``) — a decimal comma would put
    commas in the values, never only where the names have them.
    """
    header_line = sample[0][0]
    width = len(header)
    for number, text in sample[1:]:
        if '"' not in text and text.count(delimiter) + 1 != width:
            other = _splits_into(text, delimiter, width)
            if other is not None:
                raise LogFormatError(
                    _mixed_message(number, other, delimiter), field="file", line=number
                )
    for other in DELIMITERS.replace(delimiter, ""):
        in_header = [cell.count(other) for cell in header]
        if not any(in_header) or any('"' in text for _, text in sample):
            continue
        rows = [text.split(delimiter) for _, text in sample[1:]]
        if rows and all(
            len(row) == width and [c.count(other) for c in row] == in_header for row in rows
        ):
            cell = header[next(j for j, n in enumerate(in_header) if n)]
            raise LogFormatError(
                f"line {header_line}: the delimiter is inconsistent: column {cell.strip()!r} "
                f"contains {other!r} though the columns are separated by {delimiter!r} (the "
                f"rows have {other!r} in the same places); use one delimiter throughout",
                field="header",
                line=header_line,
            )


def _splits_into(text: str, delimiter: str, width: int) -> str | None:
    """The other delimiter that splits ``text`` into ``width`` fields, if one does."""
    for other in DELIMITERS.replace(delimiter, ""):
        if text.count(other) and text.count(other) + 1 == width:
            return other
    return None


def _mixed_message(line: int, other: str, delimiter: str) -> str:
    return (
        f"line {line}: the delimiter is inconsistent: this row is separated by {other!r}, "
        f"the header by {delimiter!r}; use one delimiter throughout"
    )


def sniff_decimal(rows: list[list[str]], delimiter: str) -> str:
    if delimiter == ",":
        return "."
    cells = [c for row in rows for c in row]
    comma = any(_DECIMAL_COMMA.match(c) for c in cells)
    point = any(_DECIMAL_POINT.search(c) for c in cells)
    return "," if comma and not point else "."


def _split_header(header: list[str], line: int) -> tuple[list[str], list[str]]:
    names, units = [], []
    for cell in header:
        match = _HEADER_UNIT.match(cell)
        name, unit = (match["name"], match["unit"].strip()) if match else (cell.strip(), "")
        if not name:
            raise LogFormatError(
                f"line {line}: empty column name in the header", field="header", line=line
            )
        try:
            name = check_name(name, field="header", what="column name", line=line)
        except InputError as exc:
            raise LogFormatError(exc.message, field="header", line=line) from None
        names.append(name)
        units.append(unit)
    dupes = sorted(n for n, count in Counter(names).items() if count > 1)
    if dupes:
        raise LogFormatError(
            f"line {line}: duplicate column names {dupes}", field="header", line=line
        )
    return names, units


def _columns(body: list[str], lines: list[int], delimiter: str, width: int) -> list[Sequence[str]]:
    """The body's cells column by column, every row checked to have ``width`` fields.

    Without quote characters the whole body is split at once (fast for long logs);
    otherwise each line goes through :mod:`csv`.
    """
    if not body:
        return [[] for _ in range(width)]
    joined = "\n".join(body)
    if '"' in joined:
        rows = list(csv.reader(body, delimiter=delimiter))
        counts = [len(row) for row in rows]
    else:
        rows = None
        counts = [ln.count(delimiter) + 1 for ln in body]
    for k, count in enumerate(counts):
        if count != width:
            other = None if rows is not None else _splits_into(body[k], delimiter, width)
            message = (
                _mixed_message(lines[k], other, delimiter)
                if other is not None
                else f"line {lines[k]}: {count} fields, header has {width}"
            )
            raise LogFormatError(message, field="file", line=lines[k])
    if rows is not None:
        return [list(col) for col in zip(*rows, strict=True)]
    cells = joined.replace("\n", delimiter).split(delimiter)
    return [cells[j::width] for j in range(width)]


def _parse_body(
    body: list[str],
    lines: list[int],
    delimiter: str,
    names: list[str],
    must: Mapping[str, bool],
    decimal: str,
    allowed_empty: Set[str] = frozenset(),
    masked: dict[str, list[int]] | None = None,
) -> dict[str, np.ndarray | None]:
    """Floats of the columns in ``must`` (name → strict), converted :data:`CHUNK_ROWS` rows at
    a time so that the cells held as Python strings stay a small part of the file; a
    non-strict column that is not numeric throughout is ``None``. An empty cell of a column
    in ``allowed_empty`` is NaN."""
    parts: dict[str, list[np.ndarray] | None] = {name: [] for name in must}
    for lo in range(0, max(len(body), 1), CHUNK_ROWS):
        chunk_lines = lines[lo : lo + CHUNK_ROWS]
        cells = _columns(body[lo : lo + CHUNK_ROWS], chunk_lines, delimiter, len(names))
        for j, name in enumerate(names):
            kept = parts.get(name)
            if kept is None:
                continue
            values = _parse_column(
                cells[j],
                chunk_lines,
                name,
                strict=must[name],
                decimal=decimal,
                empty_is_missing=name in allowed_empty,
            )
            if values is None:
                parts[name] = None
            else:
                if name in allowed_empty and masked is not None:  # written nan/inf: masked
                    for k, (cell, value) in enumerate(zip(cells[j], values, strict=True)):
                        if cell.strip() and not np.isfinite(value):
                            masked.setdefault(name, []).append(lo + k)
                kept.append(values)
    return {name: None if kept is None else np.concatenate(kept) for name, kept in parts.items()}


def _is_units_row(cells: list[str]) -> bool:
    filled = [c.strip() for c in cells if c.strip()]
    return bool(filled) and not any(_is_number(c) for c in filled)


def _is_number(text: str) -> bool:
    return _NUMBER.fullmatch(text) is not None or _DECIMAL_COMMA.match(text) is not None


def _parse_column(
    cells: Sequence[str],
    lines: list[int],
    name: str,
    *,
    strict: bool,
    decimal: str = ".",
    empty_is_missing: bool = False,
) -> np.ndarray | None:
    """Floats of one column; ``None`` for a non-numeric column when not ``strict``; with
    ``empty_is_missing`` an empty cell is NaN (no sample), an explicit NaN still refused.

    The whole column is converted at once; only when that fails is it walked cell by cell
    to name the first bad line.
    """
    texts = [c.replace(",", ".") for c in cells] if decimal == "," else list(cells)
    empty = _empty_cells(texts) if empty_is_missing else None
    if empty is not None:
        texts = ["nan" if e else t for t, e in zip(texts, empty, strict=True)]
    joined = "".join(texts)
    if not joined.isascii() or "_" in joined:  # only then can float() and _NUMBER disagree
        k = next((k for k, t in enumerate(texts) if _NUMBER.fullmatch(t) is None), None)
        if k is not None and not strict:
            return None
        if k is not None and _looks_numeric(texts[k]):
            raise LogFormatError(
                f"line {lines[k]}, column {name!r}: {cells[k].strip()!r} is not a plain number "
                "(ASCII digits 0-9 with an optional sign, decimal point and exponent; no digit "
                "separators)",
                field=name,
                line=lines[k],
            )
    try:
        out = np.array(texts, dtype=np.float64) if texts else np.empty(0)
    except ValueError:
        out = None
    if out is None:
        if not strict:
            return None
        for k, text in enumerate(texts):
            if _NUMBER.fullmatch(text) is None:
                shown = cells[k].strip()
                what = "empty value" if not shown else f"non-numeric value {shown!r}"
                raise LogFormatError(
                    f"line {lines[k]}, column {name!r}: {what}", field=name, line=lines[k]
                )
        out = np.array([float(t) for t in texts])  # numpy and float() disagree: trust float()
    bad = ~np.isfinite(out)
    if empty is not None:
        bad &= ~empty
    if empty_is_missing:  # a written nan/inf is a masked sample (NaN), issue 16
        out[bad] = np.nan
        return out
    if np.any(bad):
        k = int(np.argmax(bad))
        raise LogFormatError(
            f"line {lines[k]}, column {name!r}: {cells[k].strip()} is not allowed "
            "(values must be finite)",
            field=name,
            line=lines[k],
        )
    return out


def _empty_cells(texts: list[str]) -> np.ndarray | None:
    """Where the cells are empty (blank), or ``None`` when none is."""
    empty = np.fromiter((not t.strip() for t in texts), dtype=bool, count=len(texts))
    return empty if empty.any() else None


def _looks_numeric(text: str) -> bool:
    """Python would read ``text`` as a number (``1_000``, ``١٢``): worth its own message."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def _with_line(message: str, lines: list[int]) -> tuple[str, int | None]:
    """Rewrite ``at sample k`` in a Signals error as the file line."""
    match = re.search(r"at sample (\d+)", message)
    if match and int(match[1]) < len(lines):
        line = lines[int(match[1])]
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
